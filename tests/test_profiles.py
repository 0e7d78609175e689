"""Issue 9 through the Python API: the Cycles profile (Cycles 5.0's random walk tabulated, with
the Principled layers) as the default, the dipole beside it, and what each answers against
something other than itself: Cycles' own renders and tables, the linearity of the lobes, the
plane's closed form."""

import math
import os

import numpy as np
import pytest

import translucent
from helpers import CYCLES_SLAB, CYCLES_VIEW, centre_index, plane, slab_material, sphere, sun_plane

# Cycles 5.0's estimate of the Principled specular layer's albedo (its ggx_gen_schlick_ior_s,
# ggx_E, ggx_Eavg tables), IOR 1.5, Roughness 0.5, at view cosine 1 and 0.5.
CYCLES_E_SPEC = {1.0: 0.0374, 0.5: 0.0692}


def test_the_cycles_profile_is_the_default_and_the_dipole_stays_selectable():
    p, s = sun_plane(21, 0.1)
    m = translucent.Material.preset("skin1")
    assert translucent.Prt(s, m, backend="cpu").profile == "cycles"
    assert translucent.Prt(s, m, backend="cpu", profile="dipole").profile == "dipole"
    assert translucent.Prt(s, m, backend="cpu").report["profile"] == "cycles"


def test_slab_reflectance_predicts_the_cycles_slab_render():
    got = slab_material().slab_reflectance("cycles")
    for c in range(3):
        assert got[c] == pytest.approx(CYCLES_SLAB[c], rel=0.02), (c, got)
    # The dipole, for comparison, is far from it (the reason for the Cycles profile).
    dip = slab_material().slab_reflectance("dipole")
    assert max(abs(d / c - 1) for d, c in zip(dip, CYCLES_SLAB)) > 0.05


def test_prt_on_a_sun_lit_plane_gives_the_cycles_slab_at_the_centre():
    """Sun of Strength 1 at normal incidence on a 1 m plane of the slab's medium: B at the
    centre is what Cycles' slab reflects under a white world (E = pi there, L = R E / pi);
    the plane's rim leaves out the tail beyond 50 cm (< 1 % for the reddest channel)."""
    p, s = sun_plane(81, 1.0)
    m = slab_material()
    b = translucent.Prt(s, m, backend="cpu").radiosity(m)[centre_index(p)]
    w = translucent.layer_weight(0.5, 1.0, 1.01)
    assert w > 0.9999  # IOR 1.01: no specular layer to speak of
    for c in range(3):
        assert b[c] == pytest.approx(CYCLES_SLAB[c], rel=0.02), (c, b)


def test_radiance_carries_what_the_specular_layer_leaves():
    """L = W(mu) V(mu) B / pi with W = 1 - E_spec: along the normal (V = 1), and at 60 degrees,
    where the view factor V is the slab's (`test_slanted_views_see_what_cycles_renders`)."""
    p, s = sun_plane(21, 0.1)
    m = translucent.Material.preset("marble").with_layers(roughness=0.5)
    m = translucent.Material(m.sigma_a, m.sigma_s, g=0.0, eta=1.5).with_layers(roughness=0.5)
    prt = translucent.Prt(s, m, backend="cpu")
    b = prt.radiosity(m)
    v = centre_index(p)
    along = prt.radiance(m)
    np.testing.assert_allclose(along[v], b[v] * (1 - CYCLES_E_SPEC[1.0]) / math.pi, rtol=5e-3)
    eye = p[v] + np.array([0.0, math.sin(math.pi / 3), 0.5]) * 0.2
    at_60 = prt.radiance(m, eye)
    cos = float(np.dot(eye - p[v], (0.0, 0.0, 1.0)) / np.linalg.norm(eye - p[v]))
    view = (np.array(m.slab_reflectance("cycles", cos)) / np.array(m.slab_reflectance("cycles", 1.0))
            * translucent.layer_weight(0.5, 1.0, 1.5) / translucent.layer_weight(0.5, cos, 1.5))
    assert np.all(view > 1.0) and np.all(view < 1.05)  # marble: albedo 0.999, little to gain
    np.testing.assert_allclose(at_60[v], b[v] * (1 - CYCLES_E_SPEC[0.5]) * view / math.pi, rtol=5e-3)


@pytest.mark.parametrize("name", ["ketchup", "skin1", "marble"])
def test_slanted_views_see_what_cycles_renders(name):
    """Cycles' walk starts from the incoming ray refracted into the medium: a slanted view
    enters shallower and more of the light comes out than along the normal, beside what the
    specular layer leaves, W(mu), which falls (0.97 / 0.92): ketchup and skin1 brighten toward
    slanted views, marble (albedo 0.999, little absorbed either way) darkens as W does."""
    p, s = sun_plane(41, 0.1)
    m = translucent.Material.preset(name)
    prt = translucent.Prt(s, m, backend="cpu", interreflection=False)
    v = centre_index(p)
    along = prt.radiance(m)[v]
    for deg, cycles in CYCLES_VIEW[name].items():
        t = math.radians(deg)
        eye = p[v] + np.array([0.0, math.sin(t), math.cos(t)]) * 0.3
        got = prt.radiance(m, eye)[v] / along
        np.testing.assert_allclose(got, cycles, rtol=0.02 if name == "marble" else 0.03, err_msg=f"{deg} degrees")
        w_alone = translucent.layer_weight(m.roughness, math.cos(t), m.eta) / translucent.layer_weight(
            m.roughness, 1.0, m.eta)
        if name == "ketchup":
            assert np.all(np.abs(w_alone / np.array(cycles) - 1) > 0.14)


def test_the_lobes_add_up_as_cycles_weighs_them():
    """Subsurface Weight w: B = w B_walk + (1 - w) Base Color I(x); Metallic m and
    Transmission t scale both by (1 - m)(1 - t). Exact, since B is linear in the weights."""
    p, s = sun_plane(21, 0.1)
    full = translucent.Material.from_principled((0.8, 0.5, 0.3), (1.0, 0.5, 0.2), 0.01)
    prt = translucent.Prt(s, full, backend="cpu")
    b_full = prt.radiosity(full)
    irr = s.irradiance(eta=1.0)  # Cycles' exit is a plain Lambertian: no Fresnel
    half = full.with_layers(subsurface_weight=0.4)
    expect = 0.4 * b_full + 0.6 * np.array(full.base_color) * irr
    np.testing.assert_allclose(prt.radiosity(half), expect, rtol=2e-5, atol=1e-7)
    metal = full.with_layers(metallic=0.3, transmission=0.5)
    np.testing.assert_allclose(prt.radiosity(metal), 0.35 * b_full, rtol=2e-5, atol=1e-7)


def test_ior_edits_are_live_and_g_outside_cycles_range_is_an_error():
    p, s = sun_plane(21, 0.1)
    m = translucent.Material.preset("skin1")
    prt = translucent.Prt(s, m, backend="cpu")
    b = prt.radiosity(m)
    other = translucent.Material(m.sigma_a, m.sigma_s, g=0.0, eta=1.6)
    b2 = prt.radiosity(other)  # no new precompute: Cycles' exit has no Fresnel factor
    assert np.all(np.isfinite(b2)) and not np.array_equal(b, b2)
    with pytest.raises(ValueError, match="dipole"):
        prt.radiosity(translucent.Material(m.sigma_a, m.sigma_s, g=-0.3))
    with pytest.raises(ValueError, match=r"\[0, 0.9\]"):
        translucent.Prt(s, translucent.Material(m.sigma_a, m.sigma_s, g=0.95), backend="cpu")
    forward = translucent.Material(m.sigma_a, m.sigma_s, g=0.8)
    b3 = prt.radiosity(forward)
    assert np.all(b3[centre_index(p)] < b[centre_index(p)])  # forward scattering goes deeper


def test_from_principled_holds_the_inputs_cycles_reads():
    m = translucent.Material.from_principled(
        base_color=(0.9, 0.6, 0.4), radius=(1.0, 0.4, 0.2), scale=0.05, anisotropy=0.95, ior=1.45,
        roughness=0.3, subsurface_weight=0.8, metallic=0.1, transmission=0.2,
    )
    assert m.g == 0.9  # Cycles clamps the anisotropy
    assert (m.roughness, m.subsurface_weight, m.metallic, m.transmission) == (0.3, 0.8, 0.1, 0.2)
    assert m.base_color == pytest.approx((0.9, 0.6, 0.4))
    # d = radius scale / (4 pi), sigma_t = 1 / (d (1 - g)) (bssrdf_setup_radius).
    d = 1.0 * 0.05 / (4 * math.pi)
    assert sum(m.sigma_a[:1] + m.sigma_s[:1]) == pytest.approx(1 / (d * 0.1), rel=1e-9)
    for bad in (dict(metallic=1.5), dict(roughness=-0.1), dict(scale=0.0), dict(radius=(1, 0, 1)),
                dict(base_color=(float("nan"), 0.5, 0.5)), dict(specular_ior_level=2.0)):
        args = dict(base_color=0.5, radius=1.0, scale=0.1) | bad
        with pytest.raises(ValueError):
            translucent.Material.from_principled(**args)


def test_reference_and_prt_agree_for_the_cycles_profile_with_a_diffuse_lobe():
    p, t = plane(41, 0.1)
    s = translucent.Scene(p, t)
    s.add_spot_light((0.0, 0.0, 0.05), (0, 0, -1), power=5.0, spot_size=1.2, blend=0.3)
    m = translucent.Material.preset("skin1").with_layers(subsurface_weight=0.7, base_color=0.6)
    b = translucent.Prt(s, m, backend="cpu").radiosity(m)
    idx = list(range(0, len(p), 7))
    ref = translucent.reference_radiosity(s, m, rel_tol=1e-3, receivers=idx)
    err = translucent.relative_error(b[idx], ref, s.vertex_areas[idx, 0])
    assert max(err["rms"]) < 0.02, err


def test_tables_are_prepared_once_and_kept_on_disk(tmp_path):
    old = translucent.table_cache()
    try:
        assert translucent.set_table_cache(str(tmp_path)) == str(tmp_path)
        m = translucent.Material((0.5, 1.0, 2.0), 40.0, g=0.37, eta=1.44).with_layers(roughness=0.15)
        assert not translucent.profile_ready(m)
        seconds = translucent.prepare_profile(m)
        assert seconds > 0 and translucent.profile_ready(m)
        assert translucent.prepare_profile(m) == 0.0 or translucent.prepare_profile(m) < 1e-3
        files = sorted(os.listdir(tmp_path))
        assert len(files) == 2, files  # g = 0.37 lies between the tables at 0.35 and 0.40
        with pytest.raises(translucent.Cancelled):
            translucent.prepare_profile(m.with_layers(roughness=0.9), progress=lambda f: False)
    finally:
        translucent.set_table_cache(old)


@pytest.mark.parametrize("profile", ["dipole", "cycles"])
def test_the_far_side_of_a_sun_lit_marble_sphere_is_within_one_percent(profile):
    """Issue 9, point 6: a sphere of radius 10 mm in marble under a sun; vertices more than
    120 degrees from the sun see only light that travelled 5-20 mm under the surface, a
    thousandth of the lit side's B. Before: 5.7-6.7 % (dipole) and 15-30 % (Cycles' profile)
    from the ground truth there, from the area-weighted fit leaving the tail to chance and the
    support radius cutting it. Measured now: 0.3 % and 0.4-0.6 %; the lit side 0.02 %."""
    p, t = sphere(32, 10.0)  # millimetres
    s = translucent.Scene(p, t)
    sun = np.array([0.3, 0.2, -1.0]) / np.linalg.norm([0.3, 0.2, -1.0])
    s.add_sun(tuple(sun), 1.0)
    m = translucent.Material.preset("marble", mm_per_unit=1.0)
    normals = p / np.linalg.norm(p, axis=1)[:, None]
    angle = np.degrees(np.arccos(np.clip(normals @ -sun, -1, 1)))
    rng = np.random.default_rng(0)
    back = np.sort(rng.choice(np.flatnonzero(angle > 120), 16, replace=False))
    front = np.sort(rng.choice(np.flatnonzero(angle < 60), 8, replace=False))
    # The half-space model against its own ground truth: no walks through the mesh (which
    # carry light straight through a 10 mm marble sphere: tests/test_walks.py).
    prt = translucent.Prt(s, m, profile=profile, backend="cpu", walks=0 if profile == "cycles" else None)
    b = prt.radiosity(m)
    truth = translucent.reference_radiosity(s, m, rel_tol=1e-4, receivers=np.concatenate([back, front]).tolist(),
                                            profile=profile, max_nodes=20_000_000)
    w = s.vertex_areas[:, 0]
    far = translucent.relative_error(b[back], truth[:16], w[back])["rms"]
    near = translucent.relative_error(b[front], truth[16:], w[front])["rms"]
    assert truth[:16].mean() < 0.01 * truth[16:].mean()  # the far side is lit only from afar
    assert max(far) < 0.01, far
    assert max(near) < 0.002, near
    # The estimate covers what it measured, on both sides.
    assert max(prt.last_eval["error_estimate"]) >= max(max(far), max(near))


def test_the_objects_own_light_adds_where_it_can_fall_back_and_nowhere_else():
    """Interreflection (on by default with Cycles' profile, three bounces): a convex sphere
    cannot light itself, so B is unchanged to the bit; two faces of a V under a sun light each
    other, so each vertex of the V gains, by at most the series of what its partner sends."""
    p, t = sphere(12, 0.05)
    s = translucent.Scene(p, t)
    s.add_sun((0.2, 0.1, -1.0), 2.0)
    m = translucent.Material.preset("skin1")
    on = translucent.Prt(s, m, backend="cpu")
    off = translucent.Prt(s, m, backend="cpu", interreflection=False)
    # 144 rays per vertex, cast once for the first bounce; the later bounces gather over the
    # same hits (the stored operator), so they cast none.
    assert on.report["interreflection_rays"] == 144 * len(p) and off.report["interreflection_rays"] == 0
    np.testing.assert_array_equal(on.radiosity(m), off.radiosity(m))
    assert translucent.Prt(s, m, backend="cpu", profile="dipole").report["interreflection_rays"] == 0

    # A V of two 10 cm squares at 60 degrees, opening upwards, lit from above.
    n = 21
    u = np.linspace(0.0, 0.1, n, dtype=np.float32)
    a, b = np.meshgrid(u, u)
    half = math.radians(30.0)
    left = np.stack([-a.ravel() * math.sin(half), b.ravel(), a.ravel() * math.cos(half)], 1)
    right = np.stack([a.ravel() * math.sin(half), b.ravel(), a.ravel() * math.cos(half)], 1)
    idx = np.arange(n * n).reshape(n, n)
    quads = np.stack([idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()], 1)
    tl = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    pts = np.vstack([left, right])
    tris = np.vstack([tl, tl + n * n])
    normal = np.cross(pts[tris[:, 1]] - pts[tris[:, 0]], pts[tris[:, 2]] - pts[tris[:, 0]])
    tris[normal[:, 2] < 0] = tris[normal[:, 2] < 0][:, ::-1]  # both faces look up, into the V
    v = translucent.Scene(pts, tris)
    v.add_sun((0.0, 0.0, -1.0), 2.0)
    # The walks through the mesh left out of both (walks=0): with the object's own light on,
    # their term also carries its estimate through the V (another noisy estimate, not this
    # test's subject).
    on = translucent.Prt(v, m, backend="cpu", walks=0)
    off = translucent.Prt(v, m, backend="cpu", interreflection=False, walks=0)
    b_on, b_off = on.radiosity(m), off.radiosity(m)
    assert np.all(b_on >= b_off - 1e-7)
    gain = (b_on - b_off).sum(axis=0) / b_off.sum(axis=0)
    assert np.all(gain > 0.02), gain  # the faces see each other over a large solid angle
    # Bounded by the series of the partner's whole outgoing light times the receiving slab's
    # albedo, a + a^2 + ... (view factor 1).
    albedo = np.array(m.slab_reflectance("cycles"))
    assert np.all(gain < albedo / (1 - albedo)), (gain, albedo)
    assert on.report["interreflection_share"] == pytest.approx(gain.max(), rel=0.05)
