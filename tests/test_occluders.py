"""The rest of the scene (issue 30 point 1): occluders cast shadows on the previewed mesh and are
left out where they can shadow nothing. Expected values: the sun's closed form (E = 0 beneath a
blocker, E = strength elsewhere) and the dipole's half-plane integral of its own closed-form
disc integral (helpers.disc_integral), independent of the code under test."""


import numpy as np
import pytest

import translucent
from helpers import assert_shadow_edge, entering, plane, rd_total, square


def sunlit(p, t, blocker=None):
    """The mesh under a sun straight down (3 W/m^2), with `blocker` (positions, triangles) as
    an occluder named "blocker" when given."""
    s = translucent.Scene(p, t)
    s.add_sun((0.0, 0.0, -1.0), irradiance=3.0)
    if blocker is not None:
        s.add_occluder(*blocker, name="blocker")
    return s


def test_a_blocker_shadows_the_irradiance_and_what_cannot_shadow_is_left_out():
    p, t = plane(41, 2.0)
    s = translucent.Scene(p, t)
    s.add_sun((0.0, 0.0, -1.0), irradiance=2.0)
    s.add_occluder(*square(0.5, 0.5, 0.3, 0.5), name="blocker")
    s.add_occluder(*square(0.0, 0.0, -1.0, 5.0), name="floor below")
    e = s.irradiance()[:, 0]
    inside = (p[:, 0] > 0.1) & (p[:, 0] < 0.9) & (p[:, 1] > 0.1) & (p[:, 1] < 0.9)
    outside = (p[:, 0] < -0.1) | (p[:, 1] < -0.1) | (p[:, 0] > 1.1) | (p[:, 1] > 1.1)
    assert inside.sum() > 50 and np.all(e[inside] == 0.0)
    np.testing.assert_allclose(e[outside], 2.0, rtol=1e-5)
    r = s.occluders
    assert (r["objects"], r["triangles"], r["triangles_kept"]) == (2, 4, 2)
    assert r["objects_skipped"] == ["floor below"]
    # Under a world every triangle can shadow: all are kept.
    s.set_world(color=(0.1, 0.1, 0.1))
    assert s.occluders["triangles_kept"] == 4 and s.occluders["objects_skipped"] == []



def test_a_scene_without_its_lights_keeps_its_mesh_and_occluders():
    """`Scene.without_lights` (the add-on's light drag): no light and no world, and the sun
    added again is shadowed by the same blocker, as the closed form says (0 beneath, the
    strength elsewhere)."""
    p, t = plane(41, 2.0)
    s = sunlit(p, t, square(0.5, 0.5, 0.3, 0.5))
    s.set_world(color=(0.1, 0.1, 0.1))
    bare = s.without_lights()
    assert bare.light_count == 0 and bare.vertex_count == s.vertex_count
    np.testing.assert_array_equal(bare.irradiance(), 0.0)
    bare.add_sun((0.0, 0.0, -1.0), irradiance=2.0)
    e = bare.irradiance()[:, 0]
    inside = (p[:, 0] > 0.1) & (p[:, 0] < 0.9) & (p[:, 1] > 0.1) & (p[:, 1] < 0.9)
    outside = (p[:, 0] < -0.1) | (p[:, 1] < -0.1) | (p[:, 0] > 1.1) | (p[:, 1] > 1.1)
    assert inside.sum() > 50 and np.all(e[inside] == 0.0)
    np.testing.assert_allclose(e[outside], 2.0, rtol=1e-5)
    assert s.light_count == 1, "the original keeps its light"

@pytest.mark.parametrize("bad, match", [
    (lambda p, t: (np.where(np.arange(12).reshape(4, 3) == 4, np.nan, p), t), "position"),
    (lambda p, t: (p, t + 3), "triangle"),
    (lambda p, t: (p[:0], t[:0]), "positions"),
])
def test_bad_occluders_are_refused_by_name(bad, match):
    p, t = plane(5, 1.0)
    s = translucent.Scene(p, t)
    with pytest.raises(ValueError, match=match):
        s.add_occluder(*bad(*square(0, 0, 1, 1)), name="wall")


def test_prt_under_a_blockers_straight_shadow_edge_meets_the_dipoles_half_plane_integral():
    # A 40 cm marble plane under a sun straight down; a blocker 5 cm up covers x > 0: B at a
    # distance d from the edge is E_in (R_total - H(d)) on the lit side and E_in H(d) beneath.
    p, t = plane(81, 0.4)
    s = translucent.Scene(p, t)
    s.add_sun((0.0, 0.0, -1.0), irradiance=3.0)
    s.add_occluder(*square(0.15, 0.0, 0.05, 0.15), name="blocker")
    m = translucent.Material.preset("marble", mm_per_unit=1000.0)
    b = translucent.Prt(s, m, profile="dipole").radiosity(m)
    assert assert_shadow_edge(b, p, m, entering(1.3, 1.0, 3.0)) > 100


def test_an_update_under_a_new_occluder_recasts_the_light_and_meets_a_fresh_precompute():
    p, t = plane(41, 0.2)
    m = translucent.Material.preset("marble", mm_per_unit=1000.0)

    def scene(blocked):
        return sunlit(p, t, square(0.05, 0.0, 0.05, 0.05) if blocked else None)

    prt = translucent.Prt(scene(False), m, profile="dipole")
    r = prt.update(lights=scene(True))
    assert r["rays"] > 0 and r["rescaled"] is None  # the same sun, another shadow: rays again
    fresh = translucent.Prt(scene(True), m, profile="dipole").radiosity(m)
    b = prt.radiosity(m)
    assert translucent.relative_error(b, fresh, scene(True).vertex_areas[:, 0])["rms"][0] < 0.01
    assert prt.report["occluders"]["triangles_kept"] == 2
    beneath = (p[:, 0] > 0.02) & (p[:, 0] < 0.08) & (np.abs(p[:, 1]) < 0.03)
    assert np.all(b[beneath, 0] < 0.5 * b[p[:, 0] < -0.06, 0].mean())


@pytest.mark.parametrize("mode", ["render", "on_the_fly"])
def test_a_hierarchy_update_under_a_new_occluder_shadows_as_the_half_plane_integral_says(mode):
    # The hierarchy built unshadowed, then updated to a scene whose blocker covers x > 0 (a prop
    # moved in): beneath it B follows E_in H(d), beside it E_in (R_total - H(d)), as for PRT.
    p, t = plane(81, 0.4)
    m = translucent.Material.preset("marble", mm_per_unit=1000.0)

    def scene(blocked):
        return sunlit(p, t, square(0.15, 0.0, 0.05, 0.15) if blocked else None)

    h = translucent.Hierarchy(scene(False), m, profile="dipole", mode=mode, estimate_receivers=0)
    e_in = entering(1.3, 1.0, 3.0)
    row = np.flatnonzero((np.abs(p[:, 1]) < 1e-6) & (p[:, 0] > 0.01) & (p[:, 0] < 0.12))
    assert np.all(h.radiosity(m)[row, 0] > 0.9 * e_in * rd_total(m.sigma_a[0], (1 - m.g) * m.sigma_s[0], m.eta))
    h.update(lights=scene(True))
    # The hierarchy takes the irradiance at face centres (no shadow-edge refinement, unlike
    # PRT): the vertices one grid step (5 mm) from the edge are left out.
    assert assert_shadow_edge(h.radiosity(m), p, m, e_in, near=6e-3, tol=0.03) > 100
    # Taken back out: the hierarchy is lit as before the prop came.
    h.update(lights=scene(False))
    assert np.all(h.radiosity(m)[row, 0] > 0.9 * e_in * rd_total(m.sigma_a[0], (1 - m.g) * m.sigma_s[0], m.eta))


def test_shadow_linking_through_the_api_relight_and_pose():
    # Shadow linking (Cycles' blocker collection): the sun's blockers leave the square out, so
    # the irradiance is the sun's 3 W/m^2 everywhere, as with no square (closed form). A
    # transport relit by a Scene that only links the shadows recasts them (not a rescale) and
    # meets a fresh precompute; a pose on the same lights keeps the linking.
    p, t = plane(31, 2.0)
    shadowed = sunlit(p, t, square(0.5, 0.5, 0.3, 0.5))
    linked = sunlit(p, t, square(0.5, 0.5, 0.3, 0.5))
    linked.link_shadows(0, [])
    np.testing.assert_allclose(linked.irradiance(), 3.0, rtol=1e-5)
    assert np.min(shadowed.irradiance()) == 0.0
    with pytest.raises(ValueError, match="no occluder named 'lid'|no occluder named \"lid\""):
        linked.link_shadows(0, ["lid"])
    with pytest.raises(ValueError, match="light 1"):
        linked.link_shadows(1, [])
    m = translucent.Material.preset("marble")
    prt = translucent.Prt(shadowed, m, coefficients=8, profile="dipole", single_scattering=False)
    fresh = translucent.Prt(linked, m, coefficients=8, profile="dipole", single_scattering=False).radiosity(m)
    before = prt.radiosity(m)
    report = prt.update(lights=linked)
    assert report["rays"] > 0 and report["rescaled"] is None
    np.testing.assert_allclose(prt.radiosity(m), fresh, rtol=1e-5, atol=1e-9)
    assert np.abs(before - fresh).max() > 1e-3 * fresh.max()
    # The pose's transport is a first preview's (fewer samples: within 2 %), and still unshadowed
    # where the square's shadow would fall.
    prt.update(positions=p)
    rel = np.abs(prt.radiosity(m) - fresh) / fresh.max()
    assert rel.max() < 0.02, rel.max()
    assert np.abs(before - fresh).max() > 10 * np.abs(prt.radiosity(m) - fresh).max()


def test_light_linking_through_the_api_prt_single_scattering_and_a_relight():
    # Light linking (Cycles' receiver collection): the sun linked to neither the mesh nor the
    # square lights nothing, so the irradiance is 0, and so is PRT's radiosity with single
    # scattering (whose entry rays are the light's own). A transport relit by a Scene that only
    # links the light is not a rescale and goes dark; linked back to the mesh, it meets the
    # unlinked scene's (the square does not light the plane from its sunlit top either way).
    p, t = plane(31, 2.0)
    plain = sunlit(p, t, square(0.5, 0.5, 0.3, 0.5))
    dark = sunlit(p, t, square(0.5, 0.5, 0.3, 0.5))
    dark.link_light(0, [], mesh=False)
    assert np.max(dark.irradiance()) == 0.0 and np.max(plain.irradiance()) == pytest.approx(3.0, rel=1e-5)
    relit = sunlit(p, t, square(0.5, 0.5, 0.3, 0.5))
    relit.link_light(0, ["blocker"], mesh=True)
    np.testing.assert_allclose(relit.irradiance(), plain.irradiance(), rtol=1e-6, atol=1e-9)
    with pytest.raises(ValueError, match="receivers: no occluder named"):
        dark.link_light(0, ["lid"])
    with pytest.raises(ValueError, match="light 1"):
        dark.link_light(1, [])
    m = translucent.Material.preset("marble")
    prt = translucent.Prt(plain, m, coefficients=8, profile="dipole", single_scattering=True)
    lit = prt.radiosity(m)
    assert lit.max() > 0.1
    report = prt.update(lights=dark)
    assert report["rescaled"] is None
    assert np.max(np.abs(prt.radiosity(m))) == 0.0
    prt.update(lights=relit)
    np.testing.assert_allclose(prt.radiosity(m), lit, rtol=1e-5, atol=1e-9)
