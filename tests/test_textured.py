"""`Prt.radiance(base_color=...)` through the Python API (issue 30, point 2): the arguments
checked, and a uniform Base Color given per vertex is the uniform material's preview. The
per-vertex medium's accuracy against the dipole's closed form is checked in Rust
(`prt::textured`), against Cycles in `test_bpy_texture.py`."""

import math

import numpy as np
import pytest
import translucent
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import sphere, sun_plane


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


def test_a_rescaled_light_scales_the_textured_radiance_as_the_uniform_one():
    # Only the sun's strength changes (a rescale, no ray): B is linear in the light, so the
    # radiance along the normals doubles, per vertex as for the uniform material.
    p, scene = sun_plane(n=21, size=0.1)
    t = translucent.Prt(scene, _inputs(), coefficients=16, profile="cycles", walks=0, interreflection=False)
    colours = np.full((len(p), 3), 0.75)
    before = t.radiance(_inputs(0.3), base_color=colours)
    _, brighter = sun_plane(n=21, size=0.1, strength=2.0)
    t.update(lights=brighter)
    after = t.radiance(_inputs(0.3), base_color=colours)
    np.testing.assert_allclose(after, 2.0 * before, rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(after, t.radiance(_inputs(0.75)), rtol=1e-5, atol=1e-9)


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


@pytest.fixture(scope="module")
def walked():
    """A 10 mm sphere under a sun, Cycles' profile with the walks and the own light, its
    transport for a dark and a bright Base Color (both walked: their lengths lie far apart)."""
    pos, tri = sphere(10, 0.01)
    scene = translucent.Scene(pos, tri)
    scene.add_sun((0.3, 0.2, -1.0), irradiance=1.0)
    reps = [_inputs(0.5), _inputs(0.95), _inputs(0.1)]
    prt = translucent.Prt(scene, reps, samples=6000, backend="cpu", profile="cycles",
                          walk_rays=600_000, interreflection_rays=16)
    assert prt.report["walks"]["media"] >= 2
    return prt


def test_a_base_colour_changed_in_place_is_read_afresh(walked):
    # An edit keeps the last colours' places among the table's nodes; a colour array changed in
    # place must still give what a first edit with those colours gives (expected value: the
    # same call made before any other colours were seen).
    n = walked.vertex_count
    rng = np.random.default_rng(7)
    before = rng.uniform(0.05, 0.95, (n, 3)).astype(np.float32)
    after = before.copy()
    after[::3] = rng.uniform(0.05, 0.95, (len(after[::3]), 3))
    first = walked.radiance(_inputs(), base_color=after)
    first_estimate = walked.last_eval["error_estimate"]
    colours = before.copy()
    walked.radiance(_inputs(), base_color=colours)
    walked.radiance(_inputs(), base_color=colours)  # the kept places read again
    colours[:] = after
    again = walked.radiance(_inputs(), base_color=colours)
    np.testing.assert_array_equal(again, first)
    np.testing.assert_allclose(walked.last_eval["error_estimate"], first_estimate, rtol=1e-9)
    assert np.abs(first - walked.radiance(_inputs(), base_color=before)).max() > 0.0


def test_one_base_colour_per_vertex_with_the_walks_is_the_uniform_material(walked):
    # 0.5 lies on a node and is the first representative: the walks' term read along the
    # nodes (a vertex's weight between two walked lengths blended from its nodes') and the own
    # light scaled by the mean of what the vertices send on give the uniform edit's answer,
    # which reads the walks at the material's own lengths.
    n = walked.vertex_count
    uniform = walked.radiance(_inputs(0.5))
    per_vertex = walked.radiance(_inputs(0.3), base_color=np.full((n, 3), 0.5))
    np.testing.assert_allclose(per_vertex, uniform, rtol=1e-3, atol=1e-7)


@settings(max_examples=12, deadline=None, derandomize=True)
@given(low=st.sampled_from([0.0, 1e-6, 0.02, 0.5]), high=st.sampled_from([0.5, 0.98, 1.0, 3.0]),
       scale=st.sampled_from([1e-5, 0.002, 0.5]), weight=st.sampled_from([None, 0.0, 0.6]))
def test_textured_edits_with_the_walks_stay_finite_non_negative_and_gain_no_energy(walked, low, high, scale, weight):
    """Base Colours from black to beyond white (Cycles saturates them), radii far below and far
    above the sphere's size, with and without a Subsurface Weight per vertex: B and the radiance
    finite and >= 0, the estimate finite, and no energy gained: every vertex's medium returns at
    most what enters, so B <= (1 + 10 %) E_sun (the 10 % for the walks' noise)."""
    n = walked.vertex_count
    colours = np.linspace(low, high, 3 * n).reshape(n, 3).astype(np.float32)
    m = translucent.Material.from_principled(0.5, (1.0, 0.5, 0.25), scale)
    w = None if weight is None else np.full(n, weight, np.float32)
    b = walked.radiosity(m, base_color=colours, subsurface_weight=w)
    assert np.all(np.isfinite(b)) and np.all(b >= 0), b
    assert np.all(b <= 1.1), b.max()
    assert all(math.isfinite(x) and x >= 0 for x in walked.last_eval["error_estimate"])
    rad = walked.radiance(m, base_color=colours, subsurface_weight=w)
    assert np.all(np.isfinite(rad)) and np.all(rad >= 0)


@pytest.fixture(scope="module")
def facing():
    """Two 10 mm spheres 2 mm apart under a sun, one object's mesh (each lights the other: the own
    light is not nil), Cycles' profile with the own light, no walks; the second sphere's vertices
    (x > 0) are the other material's."""
    pos, tri = sphere(8, 0.01)
    both = np.concatenate([pos - (0.011, 0.0, 0.0), pos + (0.011, 0.0, 0.0)]).astype(np.float32)
    scene = translucent.Scene(both, np.concatenate([tri, tri + len(pos)]))
    scene.add_sun((0.3, 0.2, -1.0), irradiance=1.0)
    prt = translucent.Prt(scene, _inputs(0.5), samples=6000, backend="cpu", profile="cycles", walks=0,
                          interreflection_rays=64)
    return prt, both[:, 0] > 0.0


def test_other_materials_rows_beside_a_uniform_material(facing):
    # `others=` (another material's faces on the object, NaN rows for the previewed vertices):
    # the previewed vertices get what the per-vertex edit gives them with the others' colours in
    # its rows (each vertex its own medium; the others reach the previewed ones through the own
    # light alone), the others' rows NaN and counted in `skipped`. Base Colour 0.5 lies on a
    # node, so the per-vertex edit interpolates only the others' slab albedos (within 0.5 %).
    prt, other = facing
    got = {}
    for shade in (0.05, 0.95):
        others = np.where(other[:, None], np.float32(shade), np.float32(np.nan)) * np.ones((1, 3), np.float32)
        got[shade] = prt.radiance(_inputs(0.5), others=others)
        skipped = [s for s in prt.last_eval["skipped"] if "other materials" in s["what"]]
        assert skipped and f"{int(other.sum())} vertices" in skipped[0]["why"]
        merged = np.where(other[:, None], others, np.float32(0.5)).astype(np.float32)
        per_vertex = prt.radiance(_inputs(0.5), base_color=merged)
        assert np.isnan(got[shade][other]).all() and np.isfinite(got[shade][~other]).all()
        np.testing.assert_allclose(got[shade][~other], per_vertex[~other], rtol=2e-3, atol=1e-7)
    # The others' colour is seen: a bright neighbour lights the previewed sphere more than a
    # dark one, by far more than the tolerance above.
    gain = got[0.95][~other].sum(axis=0) / got[0.05][~other].sum(axis=0) - 1.0
    assert (gain > 0.01).all(), gain
    # Others of the previewed colour are the uniform edit.
    same = np.where(other[:, None], np.float32(0.5), np.float32(np.nan)) * np.ones((1, 3), np.float32)
    np.testing.assert_allclose(prt.radiance(_inputs(0.5), others=same)[~other],
                               prt.radiance(_inputs(0.5))[~other], rtol=1e-5, atol=1e-9)


def test_others_arguments_are_checked(walked):
    n = walked.vertex_count
    with pytest.raises(ValueError, match="others has 3 rows"):
        walked.radiance(_inputs(), others=np.full((3, 3), np.nan))
    bad = np.full((n, 3), np.nan)
    bad[5, 0] = 0.5
    with pytest.raises(ValueError, match="others row 5"):
        walked.radiosity(_inputs(), others=bad)
    with pytest.raises(ValueError, match="others must have shape"):
        walked.radiance(_inputs(), others=np.full((n, 2), np.nan))
    with pytest.raises(ValueError, match="others is for a uniform material"):
        walked.radiance(_inputs(), others=np.full((n, 3), np.nan), base_color=np.full((n, 3), 0.5))
    with pytest.raises(ValueError, match="others needs a material made by Material.from_principled"):
        walked.radiance(translucent.Material.preset("marble"), others=np.full((n, 3), np.nan))


def test_float32_float64_and_strided_colours_read_alike(prt):
    # A C-contiguous float32 array is read as it is, any other through float64: the same values.
    n = len(prt.radiance(_inputs()))
    rng = np.random.default_rng(3)
    wide = rng.uniform(0.05, 0.95, (n, 6))
    strided = wide.astype(np.float32)[:, ::2]  # float32, not contiguous
    assert not strided.flags["C_CONTIGUOUS"]
    a = prt.radiance(_inputs(), base_color=np.ascontiguousarray(strided))
    np.testing.assert_array_equal(prt.radiance(_inputs(), base_color=strided), a)
    np.testing.assert_array_equal(prt.radiance(_inputs(), base_color=strided.astype(np.float64)), a)
