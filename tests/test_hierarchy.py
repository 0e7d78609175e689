"""translucent.Hierarchy (Mertens 2003, issue 10): B against the ground truth on the Stanford
bunny, the modes against each other, and bad input. Expected values come from
`reference_radiosity` (brute-force integration) or from a fresh evaluation, never from the
hierarchy's own earlier output."""

import numpy as np
import pytest

import translucent
from blender_scripts.lib import models
from helpers import plane, sphere

BUNNY = models.MODELS / "stanford-bunny.obj"


def lit(p, t, light=(0.03, -0.02, 0.04)):
    scene = translucent.Scene(p, t)
    scene.add_point_light(light, power=5.0)
    scene.add_sun(direction=(0.3, 0.5, -0.8), irradiance=1.0)
    return scene


def rms(a, b, w):
    return max(translucent.relative_error(a, b, w)["rms"])


@pytest.mark.skipif(not BUNNY.exists(), reason="../shared/models is not beside the repo")
@pytest.mark.parametrize("profile", ["cycles", "dipole"])
def test_hierarchy_within_two_percent_of_the_ground_truth_on_the_bunny(profile):
    p, t = models.load("stanford-bunny.obj", diagonal=0.1)
    scene = models.standard_scene(p, t)
    rng = np.random.default_rng(3)
    idx = np.sort(rng.choice(scene.vertex_count, size=16, replace=False))
    w = scene.vertex_areas[idx, 0]
    for name in ("marble", "skimmilk", "ketchup"):
        m = translucent.Material.preset(name, mm_per_unit=1000.0)
        h = translucent.Hierarchy(scene, m, profile=profile)
        b = h.radiosity(m)[idx]
        truth, info = translucent.reference_radiosity(
            scene, m, rel_tol=1e-2, receivers=idx.tolist(), max_level=2, profile=profile, details=True
        )
        err = rms(b, truth, w)
        assert err < 0.02, (name, profile, err, h.report)
        # The ground truth's own uncertainty must lie well below the bar it judges.
        assert info["estimated_rel_error"] < 0.01, info


@pytest.mark.parametrize("profile", ["cycles", "dipole"])
def test_a_coarse_sun_lit_sphere_within_two_percent_of_the_ground_truth(profile):
    # 114 vertices on a 20 mm sphere: faces about 8 mm wide, wider than marble's diffusion
    # length, under a sun from the side (the terminator crosses faces; the dark side included).
    # Gathering at the vertices, with each face's light sampled at four points, holds the bar
    # (issue 29); the faces' centroids averaged to the vertices (Mertens §3.2) do not.
    p, t = sphere(8, 0.02)
    scene = translucent.Scene(p, t)
    scene.add_sun((0.3, -0.4, -0.87), 2.0)
    m = translucent.Material.preset("marble", mm_per_unit=1000.0)
    w = scene.vertex_areas[:, 0]
    truth, info = translucent.reference_radiosity(scene, m, rel_tol=2e-3, profile=profile, details=True)
    assert info["estimated_rel_error"] < 0.01, info
    got = {r: translucent.Hierarchy(scene, m, profile=profile, receivers=r).radiosity(m) for r in ("vertices", "faces")}
    assert rms(got["vertices"], truth, w) < 0.02, rms(got["vertices"], truth, w)
    assert rms(got["faces"], truth, w) > rms(got["vertices"], truth, w)


@pytest.mark.skipif(not BUNNY.exists(), reason="../shared/models is not beside the repo")
@pytest.mark.parametrize("profile", ["cycles", "dipole"])
def test_ketchup_over_240_bunny_vertices_within_two_percent(profile):
    # Ketchup's green and blue decay within 0.4-0.6 mm, about a face of the bunny at 10 cm:
    # B at a vertex is then mostly the light of its own faces. Over 240 vertices the faces'
    # mean (area-weighted) was 2.1-3.0 % off; one vertex on a shadow's edge held half of it.
    # Angle weights and the ring's irradiance linear across it (hierarchy::ring) fixed that.
    p, t = models.load("stanford-bunny.obj", diagonal=0.1)
    scene = models.standard_scene(p, t)
    idx = np.sort(np.random.default_rng(7).choice(scene.vertex_count, size=240, replace=False))
    w = scene.vertex_areas[idx, 0]
    m = translucent.Material.preset("ketchup", mm_per_unit=1000.0)
    b = translucent.Hierarchy(scene, m, profile=profile).radiosity(m)[idx]
    truth, info = translucent.reference_radiosity(
        scene, m, rel_tol=1e-2, receivers=idx.tolist(), max_level=2, profile=profile, details=True
    )
    assert info["estimated_rel_error"] < 0.01, info
    assert rms(b, truth, w) < 0.02, rms(b, truth, w)


@pytest.mark.skipif(not BUNNY.exists(), reason="../shared/models is not beside the repo")
@pytest.mark.parametrize("profile", ["cycles", "dipole"])
def test_vertices_on_the_rims_of_the_bunny_holes_match_the_ground_truth(profile):
    # The bunny's base has holes; a vertex on their rim has surface on one side only. The mean
    # of its faces' centroid values overstated it (+26 % for marble at one vertex), which a
    # random sample of 16 vertices had missed.
    p, t = models.load("stanford-bunny.obj", diagonal=0.1)
    scene = models.standard_scene(p, t)
    edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    rim = np.unique(unique[count == 1])
    assert len(rim) > 100, "the bunny's holes"
    idx = rim[:: len(rim) // 12][:12]
    w = scene.vertex_areas[idx, 0]
    m = translucent.Material.preset("marble", mm_per_unit=1000.0)
    b = translucent.Hierarchy(scene, m, profile=profile).radiosity(m)[idx]
    truth = translucent.reference_radiosity(
        scene, m, rel_tol=1e-2, receivers=idx.tolist(), max_level=2, profile=profile
    )
    assert rms(b, truth, w) < 0.02, rms(b, truth, w)


def test_receivers_along_a_sharp_shadow_edge_across_coarse_faces_match_the_ground_truth():
    # A 3 mm grid (faces wider than marble's decay length, so each split in quarters) under a
    # sun, a card above casting a straight, sharp shadow across the faces between the
    # vertices. Each quarter read the light at its centroid only: a lit quarter carried its
    # light up to a dark receiver 0.3 mm from the edge (+20-65 %), 6.9-8.4 % over the 29
    # receivers within 4 mm; the faces resolved along the edge (hierarchy::edges) hold 2 %.
    p, t = plane(21, 0.06)
    scene = translucent.Scene(p, t)
    scene.add_sun((0.0, 0.0, -1.0), 2.0)
    # The card covers x + 0.37 y > 1.1 mm, 10 mm above the plane.
    normal = np.array([1.0, 0.37]) / np.hypot(1.0, 0.37)
    along = np.array([-normal[1], normal[0]])
    o = normal * (0.0011 / np.hypot(1.0, 0.37))
    a, b = o - 0.1 * along, o + 0.1 * along
    card = np.array([[*a, 0.01], [*b, 0.01], [*(b + 0.1 * normal), 0.01], [*(a + 0.1 * normal), 0.01]], np.float32)
    scene.add_occluder(card, np.array([[0, 1, 2], [0, 2, 3]]), name="card")
    side = p[:, 0] + 0.37 * p[:, 1] - 0.0011
    idx = np.where((np.abs(side) < 0.004) & (np.abs(p[:, 0]) < 0.016) & (np.abs(p[:, 1]) < 0.016))[0]
    lit = scene.irradiance()[idx, 0] > 0
    assert 5 < lit.sum() < len(idx) - 5, "receivers on both sides of the edge"
    m = translucent.Material.preset("marble", mm_per_unit=1000.0)
    h = translucent.Hierarchy(scene, m, profile="cycles")
    got = h.radiosity(m)[idx]
    assert h.report["edge_faces"] > 0
    truth, info = translucent.reference_radiosity(
        scene, m, rel_tol=5e-4, receivers=idx.tolist(), max_level=6, profile="cycles", details=True
    )
    assert info["estimated_rel_error"] < 0.005, info
    assert rms(got, truth, scene.vertex_areas[idx, 0]) < 0.02, rms(got, truth, scene.vertex_areas[idx, 0])


def test_render_mode_after_a_light_move_equals_on_the_fly():
    p, t = sphere(16, 0.01)
    m = translucent.Material.preset("skin1", mm_per_unit=1000.0)
    h = translucent.Hierarchy(lit(p, t), m, profile="dipole", mode="render")
    before = h.radiosity(m)
    moved = lit(p, t, light=(-0.03, 0.01, -0.02))
    h.update(lights=moved)
    after = h.radiosity(m)
    assert h.report["relinked"] is False
    fresh = translucent.Hierarchy(moved, m, profile="dipole", mode="on_the_fly").radiosity(m)
    w = moved.vertex_areas[:, 0]
    assert rms(after, fresh, w) < 1e-5
    assert rms(before, after, w) > 0.1, "the light moved: the answer must change"


@pytest.mark.parametrize("mode", ["incremental", "on_the_fly", "render"])
def test_update_positions_after_a_deformation_equals_a_fresh_build(mode):
    p, t = sphere(16, 0.01)
    m = translucent.Material.preset("marble", mm_per_unit=1000.0)
    h = translucent.Hierarchy(lit(p, t), m, profile="dipole", mode=mode)
    before = h.radiosity(m)
    squashed = p * np.array([1.0, 1.3, 0.6], dtype=np.float32)
    h.update(positions=squashed)
    got = h.radiosity(m)
    fresh_scene = lit(squashed, t)
    fresh = translucent.Hierarchy(fresh_scene, m, profile="dipole").radiosity(m)
    w = fresh_scene.vertex_areas[:, 0]
    # The clusters stay those of the first shape (built once per topology), so even on-the-fly
    # differs a little from a hierarchy built on the new shape; render mode keeps the old links
    # by contract and is held to the accuracy bar only.
    assert rms(got, fresh, w) < (0.02 if mode == "render" else 0.01), mode
    assert rms(before, got, w) > 0.05, "the mesh deformed: the answer must change"


def test_radiance_is_exit_weight_over_pi_times_radiosity_and_report_says_what_was_done():
    p, t = sphere(8, 0.01)
    m = translucent.Material.preset("marble", mm_per_unit=1000.0)
    h = translucent.Hierarchy(lit(p, t), m, profile="dipole")
    b = h.radiosity(m)
    l = h.radiance(m)
    # Along the normal the dipole's exit weight is F_t(eta, 1) = 1 - ((eta - 1)/(eta + 1))^2.
    ft = 1.0 - ((1.3 - 1.0) / (1.3 + 1.0)) ** 2
    np.testing.assert_allclose(l, b * ft / np.pi, rtol=2e-3, atol=1e-12)
    r = h.report
    assert r["links"] == r["far_links"] + r["near_links"] > 0
    assert r["faces"] == len(t) and r["clusters"] == 2 * len(t) - 1
    assert all(0 <= e < 0.05 for e in r["error_estimate"])
    for k in ("seconds_irradiance", "seconds_links", "seconds_pull", "seconds_push", "seconds"):
        assert r[k] >= 0
    assert "Hierarchy(" in repr(h)


def test_bad_input_raises_value_error_naming_it():
    p, t = sphere(6, 0.01)
    scene = lit(p, t)
    m = translucent.Material.preset("marble", mm_per_unit=1000.0)
    with pytest.raises(ValueError, match="profile"):
        translucent.Hierarchy(scene, m, profile="jensen")
    with pytest.raises(ValueError, match="mode"):
        translucent.Hierarchy(scene, m, mode="fast")
    with pytest.raises(ValueError, match="receivers"):
        translucent.Hierarchy(scene, m, receivers="corners")
    for eps in [(-1.0, 0.1), (0.01, float("nan")), (0.0, 0.1)]:
        with pytest.raises(ValueError, match="eps"):
            translucent.Hierarchy(scene, m, eps=eps)
    h = translucent.Hierarchy(scene, m, profile="dipole")
    with pytest.raises(ValueError, match="positions"):
        h.update(positions=p[:-1])
    with pytest.raises(ValueError, match="positions"):
        h.update(positions=np.zeros((len(p), 2), dtype=np.float32))
    bad = p.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        h.update(positions=bad)
    with pytest.raises(TypeError):
        h.update(lights="sun")
    with pytest.raises(ValueError, match="eye"):
        h.radiance(m, eye=(0.0, float("inf"), 0.0))
    with pytest.raises(ValueError, match="mode"):
        h.mode = "sometimes"
    # The Hierarchy still works after the errors, with its scene unchanged.
    assert np.isfinite(h.radiosity(m)).all()


def test_the_world_by_nine_coefficients_or_shadowed_on_request():
    """Point 4: the world by its nine SH coefficients, unshadowed (Mertens §5.3: no rays),
    or traced with shadows on request; on a convex sphere, which shadows nothing, the two
    agree to the traced world's noise."""
    p, t = sphere(16, 0.01)
    s = translucent.Scene(p, t)
    s.set_world(color=(0.8, 0.9, 1.0), strength=1.0)
    m = translucent.Material.preset("marble", mm_per_unit=1000.0)
    sh = translucent.Hierarchy(s, m, profile="dipole")
    traced = translucent.Hierarchy(s, m, profile="dipole", world_shadows=True, world_samples=256)
    assert sh.report["rays"] < traced.report["rays"]
    a, b = sh.radiosity(m), traced.radiosity(m)
    assert np.abs(a / b - 1).max() < 0.05, np.abs(a / b - 1).max()


@pytest.mark.parametrize("textured", [False, True])
def test_an_evaluation_reports_progress_and_a_cancel_leaves_the_hierarchy_answering_as_before(textured):
    """`radiosity(progress=)`: the fractions rise in [0, 1] and reach 1; False at any tick stops
    the call (`Cancelled`), and the same Hierarchy then evaluates what a fresh one gives (the
    add-on cancels an edit overtaken by the next one on its worker thread)."""
    p, t = sphere(14, 0.02)
    scene = lit(p, t, light=(0.05, -0.03, 0.06))
    m0 = translucent.Material.from_principled((0.8, 0.5, 0.3), (1.0, 0.4, 0.2), 0.005)
    m1 = translucent.Material.from_principled((0.5, 0.6, 0.4), (1.0, 0.4, 0.2), 0.005)
    kw = {"base_color": np.where(p[:, :1] > 0, (0.9, 0.5, 0.3), (0.3, 0.6, 0.8)).astype(np.float32)} if textured else {}
    make = lambda: translucent.Hierarchy(scene, m0, profile="cycles", walks=True, walk_rays=200_000)  # noqa: E731
    fresh = make().radiosity(m1, **kw)
    h = make()
    seen = []
    assert np.allclose(h.radiosity(m1, progress=lambda f: seen.append(f) or True, **kw), fresh, rtol=1e-5, atol=0)
    assert seen and seen == sorted(seen) and 0.0 <= seen[0] and seen[-1] == pytest.approx(1.0)
    # Before any work (the first call comes before the work starts): always stopped.
    with pytest.raises(translucent.Cancelled):
        h.radiosity(m0, progress=lambda f: False, **kw)
    np.testing.assert_allclose(h.radiosity(m1, **kw), fresh, rtol=1e-5, atol=0)
    # Once the work has reported progress (the calls come every ~0.1 s: a short evaluation may
    # end before one comes, and then returns its answer).
    try:
        h.radiosity(m0, progress=lambda f: f <= 0.0, **kw)
    except translucent.Cancelled:
        pass
    np.testing.assert_allclose(h.radiosity(m1, **kw), fresh, rtol=1e-5, atol=0)


def test_the_estimate_states_the_noise_of_the_sampled_irradiance():
    """A floor of albedo 0.5 under the sphere sends back 30 % of its light by a sampled bounce
    (`world_samples` / 4 rays a vertex, averaged over its ring, the faces taking their
    corners'). The hierarchy's estimate carries each vertex's sampling error and the ring
    average's bias through the profile to its receivers (`report["irradiance_noise"]`):
    against `reference_radiosity` with 1024 rays (itself 0.6 % from 4096), the error it
    states follows the error measured and falls as the rays grow; at the default 64 the
    preview is within 3 % (each face's own one or two rays left it 8.7 % off); with no sampled
    light it states none."""
    p, t = sphere(16, 0.02)
    m = translucent.Material.from_principled(0.5, (1.0, 0.5, 0.25), 0.02)
    floor = np.array([[-1, -1, -0.02], [1, -1, -0.02], [1, 1, -0.02], [-1, 1, -0.02]], np.float32)
    s = translucent.Scene(p, t)
    s.add_sun((0.2, 0.1, -1.0), irradiance=2.0)
    s.add_occluder(floor, np.array([[0, 1, 2], [0, 2, 3]]), name="floor", albedo=0.5)
    receivers = np.arange(0, len(p), 4)
    ref = translucent.reference_radiosity(s, m, receivers=receivers.tolist(), world_samples=1024)
    w = s.vertex_areas[receivers, 0]
    stated, measured = {}, {}
    for samples in (4, 16, 64):
        h = translucent.Hierarchy(s, m, world_samples=samples)
        measured[samples] = err = rms(h.radiosity(m)[receivers], ref, w)
        stated[samples] = max(h.report["irradiance_noise"])
        estimate = max(h.last_eval["error_estimate"])
        assert 0.5 * err < estimate < 2.0 * err, (samples, err, estimate)
    assert stated[4] > stated[16] > stated[64], stated
    assert measured[64] < 0.03, measured
    alone = translucent.Scene(p, t)
    alone.add_sun((0.2, 0.1, -1.0), irradiance=2.0)
    h = translucent.Hierarchy(alone, m)
    h.radiosity(m)
    assert h.report["irradiance_noise"] == [0.0, 0.0, 0.0]
