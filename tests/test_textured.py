"""`Prt.radiance(base_color=...)` through the Python API (issue 30, point 2): the arguments
checked, and a uniform Base Color given per vertex is the uniform material's preview. The
per-vertex medium's accuracy against the dipole's closed form is checked in Rust
(`prt::textured`), against Cycles in `test_bpy_texture.py`."""

import numpy as np
import pytest
import translucent

from helpers import sun_plane


def _inputs(base_color=0.75):
    return translucent.Material.from_principled(base_color, (1.0, 0.5, 0.25), 0.002)


@pytest.fixture(scope="module")
def prt():
    _, scene = sun_plane(n=21, size=0.1)
    return translucent.Prt(scene, _inputs(), coefficients=16, profile="cycles", walks=0, interreflection=False)


def test_a_uniform_base_colour_per_vertex_is_the_uniform_material(prt):
    # 0.75 lies on a node of the table (12/16): the same coefficients as the uniform edit.
    n = len(prt.radiance(_inputs()))
    uniform = prt.radiance(_inputs(0.75))
    per_vertex = prt.radiance(_inputs(0.3), base_color=np.full((n, 3), 0.75))
    np.testing.assert_allclose(per_vertex, uniform, rtol=1e-5, atol=1e-9)
    assert prt.last_eval["error_estimate"] is not None


def test_base_colour_arguments_are_checked(prt):
    n = len(prt.radiance(_inputs()))
    with pytest.raises(ValueError, match="base_color has 3 rows"):
        prt.radiance(_inputs(), base_color=np.full((3, 3), 0.5))
    bad = np.full((n, 3), 0.5)
    bad[2, 0] = np.nan
    with pytest.raises(ValueError, match="base_color of vertex 2"):
        prt.radiosity(_inputs(), base_color=bad)
    with pytest.raises(ValueError, match="base_color must have shape"):
        prt.radiance(_inputs(), base_color=np.full((n, 2), 0.5))
    with pytest.raises(ValueError, match="Material.from_principled"):
        prt.radiance(translucent.Material.preset("marble"), base_color=np.full((n, 3), 0.5))


def _weighted(base_color=0.75, weight=1.0):
    return translucent.Material.from_principled(base_color, (1.0, 0.5, 0.25), 0.002, subsurface_weight=weight)


def test_one_subsurface_weight_per_vertex_is_the_uniform_material_of_that_weight(prt):
    # The uniform material holds its diffuse lobe as the profile's point mass (Cycles' walk
    # table), an independent route; per vertex the lobes are split at each vertex instead.
    n = len(prt.radiance(_inputs()))
    for w in (0.0, 0.4, 0.9):
        uniform = prt.radiance(_weighted(0.75, w))
        per_vertex = prt.radiance(_weighted(0.75, 0.2), subsurface_weight=np.full(n, w))
        np.testing.assert_allclose(per_vertex, uniform, rtol=2e-3, atol=1e-9)
    # Weight 0 is the diffuse lobe alone, w = 1 the medium alone: in between, per vertex, a
    # vertex's radiosity is the blend of the two at its own weight.
    w = np.linspace(0.0, 1.0, n)
    diffuse = prt.radiosity(_weighted(0.75), subsurface_weight=np.zeros(n))
    medium = prt.radiosity(_weighted(0.75), subsurface_weight=np.ones(n))
    mixed = prt.radiosity(_weighted(0.75), subsurface_weight=w)
    np.testing.assert_allclose(mixed, w[:, None] * medium + (1 - w[:, None]) * diffuse, rtol=1e-4, atol=1e-9)
    assert np.abs(medium - diffuse).max() > 0.05 * np.abs(diffuse).max(), "the two lobes must differ here"


def test_subsurface_weight_arguments_are_checked(prt):
    n = len(prt.radiance(_inputs()))
    with pytest.raises(ValueError, match="subsurface_weight has 3 values"):
        prt.radiance(_inputs(), subsurface_weight=np.full(3, 0.5))
    with pytest.raises(ValueError, match=r"subsurface_weight of vertex 1 is 1.5: must lie in \[0, 1\]"):
        prt.radiance(_inputs(), subsurface_weight=np.array([0.5, 1.5] + [0.5] * (n - 2)))
    with pytest.raises(ValueError, match="subsurface_weight must be a 1-D"):
        prt.radiance(_inputs(), subsurface_weight=np.full((n, 2), 0.5))
    with pytest.raises(ValueError, match="subsurface_weight per vertex needs a material made by"):
        prt.radiance(translucent.Material.preset("marble"), subsurface_weight=np.full(n, 0.5))
    # Both at once: a Base Color and a weight per vertex.
    both = prt.radiance(_inputs(), base_color=np.full((n, 3), 0.5), subsurface_weight=np.full(n, 0.5))
    assert np.isfinite(both).all() and both.shape == (n, 3)
