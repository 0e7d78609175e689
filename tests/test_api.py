"""The Python API as a bpy scripter uses it: numpy in and out, clear exceptions, closed-form
checks on a plane, cancelling, and the ground truth agreeing with PRT."""

import math
import threading

import numpy as np
import pytest

import translucent
from helpers import centre_index, fresnel_t, plane, plane_limit, sphere, sun_plane


# ---------------------------------------------------------------- bad input -> clear errors


@pytest.mark.parametrize(
    "mutate, words",
    [
        (lambda p, t: (p[:0], t), "no vertices"),
        (lambda p, t: (p, t[:0]), "no triangles"),
        (lambda p, t: (np.where(np.arange(len(p))[:, None] == 3, np.nan, p), t), "non-finite"),
        (lambda p, t: (p, np.where(t == t.max(), len(p) + 5, t)), "references vertex"),
        (lambda p, t: (p, np.where(t == 0, -1, t)), "out of range"),
        (lambda p, t: (p[:, :2], t), r"shape \(N, 3\)"),
        (lambda p, t: (p, t[:, :2]), r"shape \(M, 3\)"),
    ],
)
def test_bad_mesh_raises_value_error_saying_what_is_wrong(mutate, words):
    p, t = plane(5)
    p2, t2 = mutate(p.copy(), t.copy())
    with pytest.raises(ValueError, match=words):
        translucent.Scene(p2, t2)


def test_wrong_number_of_normals_is_rejected():
    p, t = plane(5)
    with pytest.raises(ValueError, match="normals"):
        translucent.Scene(p, t, normals=np.zeros((3, 3)))


@pytest.mark.parametrize(
    "call, words",
    [
        (lambda s: s.add_point_light((0, 0, 1), power=-5.0), "power"),
        (lambda s: s.add_sun((0, 0, 0), irradiance=1.0), "zero length"),
        (lambda s: s.add_sun((0, 0, -1), irradiance=float("nan")), "finite"),
        (lambda s: s.add_spot_light((0, 0, 1), (0, 0, -1), 10.0, spot_size=4.0), "spot_size"),
        (lambda s: s.set_world(color=(1, 1)), "3 components"),
        (lambda s: s.set_world(image=np.ones((4, 8, 2))), r"\(H, W, 3\)"),
        (lambda s: s.irradiance(eta=0.5), "eta"),
        (lambda s: s.add_mesh_light([(0, 0, 1), (1, 0, 1), (0, 1, float("nan"))], [(0, 1, 2)], 1.0), "not finite"),
        (lambda s: s.add_mesh_light([(0, 0, 1), (1, 0, 1), (0, 1, 1)], [(0, 1, 3)], 1.0), "index 3"),
        (lambda s: s.add_mesh_light([(0, 0, 1), (1, 0, 1), (0, 1, 1)], [(0, 1, 2)], -1.0), "strength"),
        (lambda s: s.add_mesh_light([(0, 0, 1), (1, 0, 1), (2, 0, 1)], [(0, 1, 2)], 1.0), "no area"),
        (lambda s: s.add_mesh_light([(0, 0, 1), (1, 0, 1), (0, 1, 1)], [(0, 1, 2)], 1.0, corner_colors=np.ones((1, 3))),
         r"corner_colors must have shape \(T, 3, 3\)"),
        (lambda s: s.add_mesh_light([(0, 0, 1), (1, 0, 1), (0, 1, 1)], [(0, 1, 2)], 1.0, corner_colors=np.ones((2, 3, 3))),
         "2 corner colours for 1 triangles"),
        (lambda s: s.add_mesh_light([(0, 0, 1), (1, 0, 1), (0, 1, 1)], [(0, 1, 2)], 1.0,
                                    corner_colors=-np.ones((1, 3, 3))), "corner colour -1"),
    ],
)
def test_bad_lights_raise_value_error(call, words):
    p, t = plane(5)
    s = translucent.Scene(p, t)
    with pytest.raises(ValueError, match=words):
        call(s)


def _lamp_against_point(add_lamp, intensities: float) -> np.ndarray:
    """A 4 cm ball 15 cm from a 1 cm lamp: its irradiance with the lamp `add_lamp(scene, lamp
    positions, triangles)` adds (64 samples of it), against a point light in the lamp's place
    of `intensities` times pi r^2 L (L = 40, colour (1, 0.5, 0.25)); area-weighted relative
    RMS per channel."""
    p, t = sphere(16, 0.04)
    q, u = sphere(24, 0.01)
    lamp = np.asarray(q) + np.array([0.15, 0.0, 0.0])
    w = np.asarray(translucent.Scene(p, t).vertex_areas)[:, 0]
    mesh = translucent.Scene(p, t)
    add_lamp(mesh, lamp, u)
    point = translucent.Scene(p, t)
    power = intensities * 4.0 * math.pi**2 * 0.01**2 * 40.0
    point.add_point_light((0.15, 0.0, 0.0), power=power, color=(1.0, 0.5, 0.25))
    a = mesh.irradiance(eta=1.0, area_samples=64)
    b = point.irradiance(eta=1.0)
    assert b[:, 0].max() > 0.0
    return np.sqrt((w[:, None] * (a - b) ** 2).sum(0) / (w[:, None] * b**2).sum(0))


def test_a_small_emissive_sphere_lights_as_the_point_light_of_its_intensity():
    # Far from it, a Lambertian sphere of radiance L and radius r is a point of radiant
    # intensity I = pi r^2 L in every direction: a point light of power 4 pi I (the core's
    # point light gives P / (4 pi d^2)). A 4 cm ball 15 cm from a 1 cm lamp (r / d <= 0.1: the
    # near field's correction is under 1 %); the lamp an occluder too, as the add-on exports
    # it, so its near side hides its far side.
    def lamp(scene, q, u):
        scene.add_mesh_light(q, u, 40.0, color=(1.0, 0.5, 0.25))
        scene.add_occluder(q, u, name="lamp")

    rms = _lamp_against_point(lamp, 1.0)
    assert np.all(rms < 0.015), rms


def test_a_small_lamp_hidden_from_shadow_rays_lights_as_twice_the_point_light():
    # The lamp above, its colour given per corner, hidden from shadow rays (and no occluder):
    # its far side is seen through its near side, so far from it the lamp is a point of twice
    # the intensity, 2 pi r^2 L.
    def lamp(scene, q, u):
        corners = np.tile(np.array([1.0, 0.5, 0.25]), (len(u), 3, 1))
        scene.add_mesh_light(q, u, 40.0, corner_colors=corners, visible_shadow=False)

    rms = _lamp_against_point(lamp, 2.0)
    assert np.all(rms < 0.015), rms


def test_bad_prt_arguments_raise_value_error():
    p, s = sun_plane(9, 0.2)
    m = translucent.Material.preset("marble")
    with pytest.raises(ValueError, match="at least one material"):
        translucent.Prt(s, [])
    with pytest.raises(ValueError):
        translucent.Prt(s, m, coefficients=0)
    with pytest.raises(ValueError):
        translucent.Prt(s, m, degree=3)
    with pytest.raises(ValueError, match="tolerance"):
        translucent.Prt(s, m, tolerance=2.0)
    prt = translucent.Prt(s, m, profile="dipole")
    with pytest.raises(ValueError, match="eta"):
        prt.radiosity(translucent.Material(m.sigma_a, m.sigma_s, eta=1.5))
    with pytest.raises(ValueError, match="profile"):
        translucent.Prt(s, m, profile="burley")
    with pytest.raises(ValueError, match="receiver index"):
        translucent.reference_radiosity(s, m, receivers=[len(p)])
    with pytest.raises(ValueError, match="same length"):
        translucent.relative_error(np.zeros((3, 3)), np.zeros((2, 3)))


# ---------------------------------------------------------------- closed forms


@pytest.mark.parametrize("theta", [0.0, 0.7])
def test_sun_on_plane_matches_closed_form_through_the_whole_api(theta):
    # 40 cm plane, marble in metres: the tail beyond 20 cm is negligible.
    p, t = plane(81, 0.4)
    s = translucent.Scene(p, t)
    s.add_sun((math.sin(theta), 0.0, -math.cos(theta)), irradiance=3.0)
    m = translucent.Material.preset("marble", mm_per_unit=1000.0)
    b = translucent.Prt(s, m, profile="dipole").radiosity(m)
    assert b.shape == (len(p), 3) and b.dtype == np.float32
    v = centre_index(p)
    sp, sa = (2.19, 2.62, 3.00), (0.0021, 0.0041, 0.0071)
    for c in range(3):
        expect = plane_limit(sa[c], sp[c], 1.3, math.cos(theta), 3.0)
        assert b[v, c] == pytest.approx(expect, rel=0.01)


def test_radiance_is_fresnel_over_pi_times_radiosity():
    p, s = sun_plane(21, 0.1)
    m = translucent.Material.preset("skin1")
    prt = translucent.Prt(s, m, profile="dipole", single_scattering=False)  # L_d alone
    b = prt.radiosity(m)
    eye = np.array([0.0, 0.3, 0.3])
    l = prt.radiance(m, eye)
    for v in (0, centre_index(p), len(p) - 1):
        w = eye - p[v]
        cos_o = w[2] / np.linalg.norm(w)
        np.testing.assert_allclose(l[v], b[v] * fresnel_t(1.3, cos_o) / math.pi, rtol=1e-5)
    assert prt.last_eval["seconds"] > 0
    along_normal = prt.radiance(m)
    np.testing.assert_allclose(along_normal, b * fresnel_t(1.3, 1.0) / math.pi, rtol=1e-5)
    assert len(prt.last_eval["error_estimate"]) == 3


# ---------------------------------------------------------------- PRT against ground truth


def test_prt_matches_reference_on_a_lit_plane_with_a_shadow_edge():
    p, t = plane(41, 0.1)
    s = translucent.Scene(p, t)
    # A spot light makes the irradiance vary across the plane.
    s.add_spot_light((0.0, 0.0, 0.05), (0, 0, -1), power=5.0, spot_size=1.2, blend=0.3)
    m = translucent.Material.preset("skin1", mm_per_unit=1000.0)
    b = translucent.Prt(s, m, coefficients=32).radiosity(m)
    idx = list(range(0, len(p), 7))
    ref = translucent.reference_radiosity(s, m, rel_tol=1e-3, receivers=idx)
    err = translucent.relative_error(b[idx], ref, s.vertex_areas[idx, 0])
    assert max(err["rms"]) < 0.02, err


# ---------------------------------------------------------------- progress, cancel, GIL


def test_progress_is_reported_and_false_cancels():
    p, s = sun_plane(31, 0.2)
    m = translucent.Material.preset("marble")
    seen = []
    translucent.Prt(s, m, progress=lambda f: seen.append(f))
    assert seen[0] == 0.0 and seen[-1] == 1.0 and seen == sorted(seen)
    with pytest.raises(translucent.Cancelled):
        translucent.Prt(s, m, progress=lambda f: f < 0.5)


def test_exception_in_progress_callback_propagates():
    p, s = sun_plane(11, 0.2)

    def boom(f):
        raise KeyError("from the callback")

    with pytest.raises(KeyError, match="from the callback"):
        translucent.Prt(s, translucent.Material.preset("marble"), progress=boom)


def test_precompute_releases_the_gil():
    p, s = sun_plane(101, 0.2)
    m = translucent.Material.preset("marble")
    ticks = 0
    done = threading.Event()

    def count():
        nonlocal ticks
        while not done.is_set():
            ticks += 1

    th = threading.Thread(target=count)
    th.start()
    try:
        translucent.Prt(s, m, far_field=0.0)
    finally:
        done.set()
        th.join()
    assert ticks > 1000


def test_a_first_preview_is_the_half_space_answer_on_fewer_samples_and_says_what_it_leaves_out():
    """`Prt(first_preview=True)`: the half-space profile on at most 150,000 samples, with a
    cheap own light and no walks. On a sun-lit plane (where the half-space answer is the exact
    one) it meets the dipole's closed form as the full precompute does; with Cycles' profile it
    reports the walks left out for the full precompute, and asking for them with it is
    refused."""
    p, t = plane(81, 0.4)
    s = translucent.Scene(p, t)
    s.add_sun((0.0, 0.0, -1.0), irradiance=3.0)
    m = translucent.Material.preset("marble", mm_per_unit=1000.0)
    first = translucent.Prt(s, m, profile="dipole", first_preview=True)
    assert first.report["first_preview"] and first.report["samples"] <= 150_000
    b = first.radiosity(m)
    v = centre_index(p)
    sp, sa = (2.19, 2.62, 3.00), (0.0021, 0.0041, 0.0071)
    for c in range(3):
        assert b[v, c] == pytest.approx(plane_limit(sa[c], sp[c], 1.3, 1.0, 3.0), rel=0.01)
    # Cycles' profile: no walk, named as left out for the full precompute; the own light on
    # 16 rays a vertex (4 x 4 strata), or left out where asked.
    q, ts = sphere(12, 0.05)
    sc = translucent.Scene(q, ts)
    sc.add_sun((0.2, 0.1, -1.0), 2.0)
    skin = translucent.Material.preset("skin1")
    c = translucent.Prt(sc, skin, backend="cpu", first_preview=True)
    assert c.report["walks"] is None and not c.report["single_scattering"]
    assert 0 < c.report["interreflection_rays"] <= 16 * sc.vertex_count
    c.radiance(skin)
    skipped = {k["what"]: k["why"] for k in c.last_eval["skipped"]}
    assert "first preview" in skipped["walks through the mesh"], skipped
    assert "the object's own light" not in skipped, skipped
    direct = translucent.Prt(sc, skin, backend="cpu", first_preview=True, interreflection=False)
    assert direct.report["interreflection_rays"] == 0
    assert not translucent.Prt(sc, skin, backend="cpu").report["first_preview"]
    with pytest.raises(ValueError, match="first_preview"):
        translucent.Prt(sc, skin, first_preview=True, walks=8)
    assert translucent.Prt(sc, skin, first_preview=True, interreflection=True).report["first_preview"]
    assert not c.report["world_unshadowed"], "no world here: nothing to say about its shadows"


def test_a_first_preview_takes_the_world_unshadowed_and_says_so():
    """Under a world a first preview reads it by its nine spherical-harmonic coefficients,
    unshadowed (no world rays); on a convex sphere, which shadows nothing, that is the traced
    world's answer (the full precompute's, which traces it) to the noise of its 64 rays a point."""
    q, ts = sphere(16, 0.01)
    s = translucent.Scene(q, ts)
    s.set_world(color=(0.8, 0.9, 1.0), strength=1.0)
    m = translucent.Material.preset("marble", mm_per_unit=1000.0)
    first = translucent.Prt(s, m, profile="dipole", first_preview=True)
    full = translucent.Prt(s, m, profile="dipole")
    assert first.report["world_unshadowed"] and not full.report["world_unshadowed"]
    assert first.report["rays"] == 0 and full.report["rays"] > 0, (first.report["rays"], full.report["rays"])
    b_first, b_full = first.radiosity(m), full.radiosity(m)
    skipped = {k["what"]: k["why"] for k in first.last_eval["skipped"]}
    assert "unshadowed" in skipped["the world's shadows"], skipped
    assert "the world's shadows" not in {k["what"] for k in full.last_eval["skipped"]}
    err = translucent.relative_error(b_first, b_full, s.vertex_areas)["rms"]
    assert max(err) < 0.02, err
