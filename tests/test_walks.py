"""Issue 12 through the Python API: Cycles' random walk traced inside the mesh, as a reference
(`reference_radiance`) and as the geometry term of PRT (`Prt(..., walks=...)`), against
what it must agree with: Cycles' slab render, the half-space model where the surface is flat,
the walks at every vertex where it is not; the skip test; determinism; bad input."""

import math

import numpy as np
import pytest

import translucent
from helpers import CYCLES_SLAB, centre_index, slab_material, sphere, sun_plane


def test_walks_through_an_open_plane_give_the_cycles_slab_render():
    """An open plane is a half-space for the walks (nothing below to leave through): at the
    centre of a sun-lit 1 m plane (irradiance 1) the radiance along the normal times pi is the
    slab albedo Cycles renders (Blender 5.0.1: 0.604, 0.433, 0.244)."""
    p, s = sun_plane(n=41, size=1.0)
    c = centre_index(p)
    m = slab_material()
    radiance, d = translucent.reference_radiance(s, m, walks=20_000, receivers=[c], details=True)
    got = radiance[0] * math.pi / translucent.layer_weight(m.roughness, 1.0, m.eta)
    se = d["std_error"][0] * math.pi
    assert np.all(se < 0.01 * got)
    assert np.all(np.abs(got - CYCLES_SLAB) <= 0.02 * np.array(CYCLES_SLAB) + 3 * se), got
    assert d["walks"] == 3 * 20_000 and d["rays"] > d["walks"]


def test_the_same_seed_gives_the_same_walks():
    p, t = sphere(10, 0.01)
    s = translucent.Scene(p, t)
    s.add_sun((0.0, 0.0, -1.0), 1.0)
    m = translucent.Material.preset("skin1")
    a = translucent.reference_radiance(s, m, walks=16)
    b = translucent.reference_radiance(s, m, walks=16)
    c = translucent.reference_radiance(s, m, walks=16, seed=3)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_flat_neighbourhoods_are_not_walked():
    """The skip test of point 4: a large plane is flat within the walks' reach everywhere, so no
    vertex is walked and the preview is the half-space profile's to the bit, except on its open
    rim (where the walks go round the edge): its 160 vertices are sharp, walked one by one; a
    small sphere is curved everywhere, so every candidate vertex is walked. (Both precomputes
    take the same samples: by default the walks' run takes fewer.)"""
    p, s = sun_plane(n=41, size=1.0)
    m = translucent.Material.preset("skin1")
    flat = translucent.Prt(s, m, backend="cpu", samples=500_000)
    walks = flat.report["walks"]
    assert walks["walked_vertices"] == 0 and walks["skipped_flat"] > 0
    assert walks["sharp_vertices"] == 4 * 40 and walks["rays"] > 0
    lo, hi = p.min(0), p.max(0)
    rim = np.any(np.isclose(p[:, :2], lo[:2]) | np.isclose(p[:, :2], hi[:2]), axis=1)
    assert rim.sum() == 160
    half = translucent.Prt(s, m, backend="cpu", walks=0, samples=500_000).radiosity(m)
    np.testing.assert_array_equal(flat.radiosity(m)[~rim], half[~rim])

    ps, ts = sphere(12, 0.005)
    sp = translucent.Scene(ps, ts)
    sp.add_sun((0.0, 0.0, -1.0), 1.0)
    curved = translucent.Prt(sp, m, backend="cpu").report["walks"]
    assert curved["skipped_flat"] == 0 and curved["walked_vertices"] > 0


def test_prt_with_walks_follows_the_walks_where_light_goes_through():
    """A 6 mm marble sphere lit from one side: light crosses it, which the half-space profile
    cannot see (its far side is dark). PRT with walks against the walks at every vertex
    (20x more walks per vertex, no kernel): within 5 %, and far closer than the half-space
    preview, which the error estimate states."""
    p, t = sphere(12, 3.0)  # millimetres
    s = translucent.Scene(p, t)
    s.add_sun((0.0, 0.0, -1.0), 1.0)
    m = translucent.Material.preset("marble", mm_per_unit=1.0)
    w = s.vertex_areas[:, 0]
    truth = translucent.reference_radiance(s, m, walks=1000)
    k = translucent.layer_weight(m.roughness, 1.0, m.eta) / math.pi
    walked = translucent.Prt(s, m, backend="cpu", interreflection=False, walk_rays=5_000_000)
    halfspace = translucent.Prt(s, m, backend="cpu", interreflection=False, walks=0)
    err_walked = max(translucent.relative_error(walked.radiosity(m) * k, truth, w)["rms"])
    err_half = max(translucent.relative_error(halfspace.radiosity(m) * k, truth, w)["rms"])
    assert err_walked < 0.05, err_walked
    assert err_half > 3 * err_walked, (err_half, err_walked)
    assert walked.report["walks"]["walks_per_vertex"] >= 16
    # The estimate states the term's own noise, and covers what was measured.
    assert max(walked.last_eval["error_estimate"]) >= max(walked.report["walks"]["noise"])
    assert max(walked.last_eval["error_estimate"]) >= 0.7 * err_walked


def test_an_edit_beyond_the_walked_lengths_asks_for_a_refresh():
    """The geometry term is carried to edits by diffusion length between the three walked
    channels; an edit that takes a channel's length 3x beyond them says so."""
    p, t = sphere(12, 0.01)
    s = translucent.Scene(p, t)
    s.add_sun((0.0, 0.0, -1.0), 1.0)
    m = translucent.Material.from_principled(base_color=(0.8, 0.6, 0.5), radius=(1.0, 0.6, 0.4), scale=0.004)
    prt = translucent.Prt(s, m, backend="cpu", walks=16)
    prt.radiosity(m)
    assert not prt.refresh_advised
    far = translucent.Material.from_principled(base_color=(0.8, 0.6, 0.5), radius=(1.0, 0.6, 0.4), scale=0.02)
    prt.radiosity(far)
    assert prt.refresh_advised
    assert max(prt.last_eval["error_estimate"]) >= 1.0


def test_media_beyond_the_walked_lengths_are_walked_beside_the_first():
    """A thin lens (6 mm wide, 0.6 mm thick) under a sun: a bright medium's light crosses it,
    a dark one's does not, so what the walks add differs far more than a diffusion length
    can carry. Precomputed for both (as for a textured Base Color's range), the bright one is
    walked too, the rays shared, and an edit to it is within 10 % of the walks at every vertex
    (`reference_radiance`, an independent brute-force walk) with no refresh asked; walked for
    the dark one alone (`walk_media=1`: the others only set the basis), the same edit is read
    from the dark one's walks, flagged, and 2.5x as far off. A moved light relights both."""
    p, t = sphere(16, 0.003)
    p = p * np.array([1.0, 1.0, 0.1], np.float32)
    s = translucent.Scene(p, t)
    s.add_sun((0.0, 0.0, -1.0), 1.0)
    w = s.vertex_areas[:, 0]

    def grey(b):
        return translucent.Material.from_principled(base_color=(b, b, b), radius=(1.0, 1.0, 1.0), scale=0.001)

    dark, bright = grey(0.3), grey(0.95)
    truth = translucent.reference_radiance(s, bright, walks=1000)
    k = translucent.layer_weight(bright.roughness, 1.0, bright.eta) / math.pi
    both = translucent.Prt(s, [dark, bright], backend="cpu", interreflection=False, walk_rays=2_000_000)
    err_both = max(translucent.relative_error(both.radiosity(bright) * k, truth, w)["rms"])
    assert not both.refresh_advised
    walks = both.report["walks"]
    assert walks["media"] == 2 and 0 < walks["rays"] <= 1.1 * 2_000_000, walks
    alone = translucent.Prt(s, [dark, bright], backend="cpu", interreflection=False, walk_rays=2_000_000,
                            walk_media=1)
    err_alone = max(translucent.relative_error(alone.radiosity(bright) * k, truth, w)["rms"])
    assert alone.refresh_advised and alone.report["walks"]["media"] == 1
    assert err_both < 0.10, err_both
    assert err_alone > 2.5 * err_both, (err_alone, err_both)
    # The estimate states the noise of the walks it read, and covers what was measured.
    assert 0.5 * err_both <= max(both.last_eval["error_estimate"]) < 1.0
    # A moved light relights both media from their records, no walk traced.
    side = translucent.Scene(p, t)
    side.add_sun((0.6, 0.0, -0.8), 1.0)
    update = both.update(lights=side)
    assert update["walks_traced"] == 0 and both.report["walks"]["media"] == 2, update
    err_side = max(translucent.relative_error(both.radiosity(bright) * k,
                                              translucent.reference_radiance(side, bright, walks=1000), w)["rms"])
    assert err_side < 0.10 and not both.refresh_advised, err_side


def test_bad_walk_input_is_a_clear_error():
    p, s = sun_plane(n=11, size=0.1)
    m = translucent.Material.preset("skin1")
    with pytest.raises(ValueError, match="dipole"):
        translucent.reference_radiance(s, m, profile="dipole")
    with pytest.raises(ValueError):
        translucent.reference_radiance(s, m, walks=-1)
    with pytest.raises(ValueError):
        translucent.reference_radiance(s, m, walks=0)
    with pytest.raises(ValueError, match="out of range"):
        translucent.reference_radiance(s, m, receivers=[len(p)])
    with pytest.raises(ValueError, match="Cycles"):
        translucent.Prt(s, m, profile="dipole", walks=16)
    with pytest.raises(ValueError):
        translucent.Prt(s, m, walks=-3)
    with pytest.raises(ValueError, match="walk_media"):
        translucent.Prt(s, m, walk_media=0)


def test_the_walks_keep_to_their_ray_budget():
    """The budget is what the precompute's time is planned by: the rays cast stay within it
    (plus a tenth for the first pass's estimate), whatever the material's reach. (Found on the
    open teapot at 100 mm per unit: a first pass that walked nothing once let skin1 cast 70
    times its budget.)"""
    p, t = sphere(16, 0.01)
    s = translucent.Scene(p, t)
    s.add_sun((0.0, 0.0, -1.0), 1.0)
    for name in ("marble", "skin1", "ketchup"):
        m = translucent.Material.preset(name)
        w = translucent.Prt(s, m, backend="cpu", interreflection=False, walk_rays=2_000_000).report["walks"]
        assert 0 < w["rays"] <= 1.1 * 2_000_000, (name, w)


@pytest.mark.parametrize("sigma_a, sigma_s", [(1e-6, 1e4), (1e3, 1e3), (1e-6, 1e-3), (0.0, 50.0)])
def test_walks_stay_finite_on_stiff_and_extreme_media(sigma_a, sigma_s):
    """Stiff (10^4 per unit: walks leave at once), dark (albedo 0.5 at 10^3), nearly transparent
    (mean free path 1000x the object: walks cross it and leave) and without absorption: B finite
    and non-negative, the reference as well, the ray budget kept, no error."""
    p, t = sphere(10, 0.01)
    s = translucent.Scene(p, t)
    s.add_sun((0.0, 0.0, -1.0), 1.0)
    m = translucent.Material(sigma_a, sigma_s, g=0.0, eta=1.4)
    prt = translucent.Prt(s, m, backend="cpu", walk_rays=300_000)
    b = prt.radiosity(m)
    assert np.all(np.isfinite(b)) and b.min() >= 0
    w = prt.report["walks"]
    assert w["rays"] <= 1.1 * 300_000 + 16 * 1000 * 256
    ref = translucent.reference_radiance(s, m, walks=8)
    assert np.all(np.isfinite(ref)) and ref.min() >= 0
    assert all(math.isfinite(e) for e in prt.last_eval["error_estimate"])


def test_a_part_sunk_into_another_is_walked_as_its_own_class():
    """A 1.5 mm marble sphere sunk a third of its height into a 4 mm one (an eyeball in a head),
    lit from above. The walks from the sunk part leave into the large sphere's inside, in the
    dark (they cross the large sphere's surface, inside the small one, before any other: Cycles'
    exit at the first surface crossed, and what tunnels on from there leaves the mesh), where the
    half-space profile sees the lit surface around it. PRT with walks: dark there (measured 1e-4
    of the lit part's level; the half-space 0.4-0.5 of it: the lit part gains the large sphere's
    light through the tunnel), and on the small sphere as a whole against the walks at every
    vertex (no kernel)."""
    pb, tb = sphere(16, 4.0)
    ps, ts = sphere(8, 1.5)
    ps = ps + np.array([0.0, 0.0, 3.8], np.float32)
    p, t = np.vstack([pb, ps]), np.vstack([tb, ts + len(pb)])
    s = translucent.Scene(p, t)
    s.add_sun((0.3, 0.0, -1.0), 1.0)
    m = translucent.Material.preset("marble", mm_per_unit=1.0)
    w = s.vertex_areas[:, 0]
    small = np.arange(len(pb), len(p))
    inside = np.linalg.norm(p[small], axis=1) < 4.0
    truth = translucent.reference_radiance(s, m, walks=400, receivers=small.tolist())
    k = translucent.layer_weight(m.roughness, 1.0, m.eta) / math.pi
    walked = translucent.Prt(s, m, backend="cpu", interreflection=False, walk_rays=3_000_000)
    half = translucent.Prt(s, m, backend="cpu", interreflection=False, walks=0)
    # The sunk part walked closer than the rest (a second pass), or every vertex walked.
    report = walked.report["walks"]
    assert report["refined_vertices"] > 0 or report["walked_vertices"] == s.vertex_count, report
    bw, bh = (walked.radiosity(m) * k)[small], (half.radiosity(m) * k)[small]
    lit = truth[~inside].mean(axis=0)
    assert np.all(truth[inside].mean(axis=0) < 0.01 * lit), truth[inside].mean(axis=0)
    assert np.all(bw[inside].mean(axis=0) < 0.05 * lit), (bw[inside].mean(axis=0), lit)
    assert np.all(bh[inside].mean(axis=0) > 0.3 * lit), (bh[inside].mean(axis=0), lit)
    err = max(translucent.relative_error(bw, truth, w[small])["rms"])
    err_half = max(translucent.relative_error(bh, truth, w[small])["rms"])
    assert err < 0.12, (err, err_half)
    assert err_half > 3 * err, (err_half, err)


def test_two_seeds_give_two_previews_whose_difference_the_walks_noise_states():
    """`Prt(seed=)`: the same seed gives the same preview; another gives an independent one. A
    sun-lit marble sphere (no occluder: the irradiance is exact, so the walks are the only
    random part) differs between two seeds by what the stated walks' noise says: the RMS of the
    difference over sqrt(2) (one preview's noise) within [0.5, 1.5] of `report["walks"]["noise"]`.
    Measured on two seeds, not taken from the code's own statement."""
    p, t = sphere(12, 3.0)
    s = translucent.Scene(p, t)
    s.add_sun((0.3, 0.0, -1.0), 1.0)
    m = translucent.Material.preset("marble", mm_per_unit=1.0)
    w = s.vertex_areas[:, 0].astype(np.float64)

    def run(seed):
        prt = translucent.Prt(s, m, backend="cpu", interreflection=False, walk_rays=400_000, seed=seed)
        return prt.radiosity(m).astype(np.float64), np.array(prt.report["walks"]["noise"])

    a, noise = run(0)
    np.testing.assert_array_equal(a, run(0)[0])
    b, _ = run(1)
    measured = np.sqrt((w[:, None] * (a - b) ** 2).sum(0) / (w[:, None] * a**2).sum(0)) / math.sqrt(2)
    assert np.all(measured > 0.5 * noise) and np.all(measured < 1.5 * noise), (measured, noise)
    with pytest.raises(ValueError, match="seed"):
        translucent.Prt(s, m, seed=-1)
