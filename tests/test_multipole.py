"""Issue 31, point 2, through the Python API and the add-on: the multipole profile (Donner and
Jensen 2005) as `profile="multipole"`, reading a material's depth and a thin layer over it
(`Material.with_stack`). Expected values: the pole sums' closed totals (helpers.slab_totals,
helpers.layered_total, written apart from the code) on a sun-lit plane, and the ground truth
(`reference_radiosity`, a brute-force integration of the same profile) on a sphere. The
multipole's own check against a brute-force walk through the slab is in Rust
(profiles::layered::against_the_walk)."""

import math

import numpy as np
import pytest

import translucent
from helpers import boundary_a, centre_index, fresnel_t, layered_total, slab_totals, sphere, sun_plane

MARBLE_MM = translucent.Material.preset("marble", mm_per_unit=1.0)
SKIN_MM = translucent.Material.preset("skin1", mm_per_unit=1.0)


def slab(thickness: float) -> translucent.Material:
    return MARBLE_MM.with_stack(thickness)


def layered(top_thickness: float = 1.5) -> translucent.Material:
    return MARBLE_MM.with_stack(top=SKIN_MM, top_thickness=top_thickness)


def test_the_slab_reflectance_is_the_pole_sum_and_a_half_space_is_the_dipole():
    a = boundary_a(MARBLE_MM.eta)[0]
    ft = fresnel_t(MARBLE_MM.eta, 1.0)
    got = slab(4.0).slab_reflectance("multipole")
    for c in range(3):
        expect = ft * slab_totals(MARBLE_MM.sigma_a[c], MARBLE_MM.sigma_s[c], 4.0, a, a)[0]
        assert got[c] == pytest.approx(expect, rel=1e-6), (c, got)
    half = MARBLE_MM.slab_reflectance("multipole")
    np.testing.assert_allclose(half, MARBLE_MM.slab_reflectance("dipole"), rtol=1e-9)
    # A 4 mm slab of marble lets red through its floor: over 10 % below the half-space.
    assert got[0] < 0.9 * half[0]
    top = layered().slab_reflectance("multipole")
    for c in range(3):
        expect = ft * layered_total((SKIN_MM.sigma_a[c], SKIN_MM.sigma_s[c], 1.5),
                                    (MARBLE_MM.sigma_a[c], MARBLE_MM.sigma_s[c], math.inf), MARBLE_MM.eta)
        assert top[c] == pytest.approx(expect, rel=1e-5), (c, top)


def test_prt_and_the_hierarchy_give_the_closed_form_on_a_sun_lit_plane():
    """A 200 mm plane, 2.5 mm grid, a sun at normal incidence: B at the centre is
    F_t(1) E R_total of the stack, the tail beyond 100 mm negligible."""
    p, s = sun_plane(81, 200.0)
    v = centre_index(p)
    ft = fresnel_t(MARBLE_MM.eta, 1.0)
    prt = translucent.Prt(s, slab(4.0), profile="multipole", backend="cpu")
    assert prt.profile == "multipole"
    hier = translucent.Hierarchy(s, slab(4.0), profile="multipole")
    a = boundary_a(MARBLE_MM.eta)[0]
    for m, totals in [
        (slab(4.0), [slab_totals(MARBLE_MM.sigma_a[c], MARBLE_MM.sigma_s[c], 4.0, a, a)[0] for c in range(3)]),
        (layered(), [layered_total((SKIN_MM.sigma_a[c], SKIN_MM.sigma_s[c], 1.5),
                                   (MARBLE_MM.sigma_a[c], MARBLE_MM.sigma_s[c], math.inf), MARBLE_MM.eta)
                     for c in range(3)]),
    ]:
        expect = ft * np.array(totals)
        for name, b in [("prt", prt.radiosity(m)[v]), ("hierarchy", hier.radiosity(m)[v])]:
            np.testing.assert_allclose(b, expect, rtol=0.015, err_msg=name)


def test_prt_matches_the_ground_truth_on_a_sphere_with_a_layer():
    p, t = sphere(16, 10.0)  # millimetres, 482 vertices
    s = translucent.Scene(p, t)
    s.add_sun((0.3, 0.2, -1.0), 1.0)
    m = layered(1.5)
    prt = translucent.Prt(s, m, profile="multipole", backend="cpu")
    b = prt.radiosity(m)
    idx = list(range(0, len(p), len(p) // 12))
    truth = translucent.reference_radiosity(s, m, rel_tol=3e-3, receivers=idx, profile="multipole")
    err = translucent.relative_error(b[idx], truth, s.vertex_areas[idx, 0])
    assert max(err["rms"]) < 0.02, err
    # The half-space answer is further off than that: the layer is seen.
    half = translucent.Prt(s, MARBLE_MM, profile="multipole", backend="cpu").radiosity(MARBLE_MM)
    assert max(translucent.relative_error(half[idx], truth, s.vertex_areas[idx, 0])["rms"]) > 0.05


def test_bad_stacks_raise_value_errors_naming_the_argument():
    with pytest.raises(ValueError, match="thickness = 0"):
        MARBLE_MM.with_stack(0.0)
    with pytest.raises(ValueError, match="thickness = NaN"):
        MARBLE_MM.with_stack(float("nan"))
    with pytest.raises(ValueError, match="top_thickness"):
        MARBLE_MM.with_stack(top=SKIN_MM)
    with pytest.raises(ValueError, match="top"):
        MARBLE_MM.with_stack(top_thickness=1.0)
    with pytest.raises(ValueError, match="top_layer.thickness"):
        MARBLE_MM.with_stack(top=SKIN_MM, top_thickness=-1.0)
    # Thinner than its source depth 1/sigma_t' (skin1: about 1.2 mm in red): refused when the
    # profile is built, naming the channel.
    thin = MARBLE_MM.with_stack(top=SKIN_MM, top_thickness=0.05)
    with pytest.raises(ValueError, match="channel 0.*source depth"):
        thin.slab_reflectance("multipole")
    # The other profiles read no stack: the same answer as the half-space.
    np.testing.assert_allclose(thin.slab_reflectance("dipole"), MARBLE_MM.slab_reflectance("dipole"))
    assert thin.thickness == math.inf and thin.top_layer[2] == 0.05
    with pytest.raises(ValueError, match="single scattering joins the dipole only"):
        p, s = sun_plane(11, 10.0)
        translucent.Prt(s, MARBLE_MM, profile="multipole", single_scattering=True, backend="cpu")


def test_a_layer_table_can_be_built_ahead_of_an_edit():
    # The add-on builds a new layer's tables on a worker thread while a slider moves
    # (prepare_profile releases the GIL), then edits without waiting.
    m = MARBLE_MM.with_stack(top=SKIN_MM, top_thickness=1.834)  # a stack no other test builds
    assert not translucent.profile_ready(m, "multipole")
    assert translucent.profile_ready(m, "dipole") and translucent.profile_ready(MARBLE_MM.with_stack(4.0), "multipole")
    assert translucent.prepare_profile(m, profile="multipole") > 0.05
    assert translucent.profile_ready(m, "multipole")
    assert translucent.prepare_profile(m, profile="multipole") < 0.05  # kept
    with pytest.raises(ValueError, match="source depth"):
        translucent.prepare_profile(MARBLE_MM.with_stack(top=SKIN_MM, top_thickness=0.05), profile="multipole")
    with pytest.raises(ValueError, match="profile"):
        translucent.profile_ready(m, "bogus")
