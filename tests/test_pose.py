"""`Prt.update(positions=...)`: a pose of the precomputed mesh (issue 29, point 3). The samples,
irradiance and transport are computed on the posed mesh; the walks and the object's own light
are carried (read on the same triangles, none traced). Judged against what is independent of
the update: a rigid motion of the mesh with its lights changes nothing physical (the rest
pose's preview is the answer), and the walk reference `reference_radiance` on a bent mesh
(Cycles' walk traced inside the posed mesh, no basis, no kernels)."""

import math

import numpy as np
import pytest

import translucent
from helpers import sphere

SKIN = translucent.Material.preset("skin1", mm_per_unit=1000.0)  # metres
RAYS = 3_000_000


def egg():
    """A 1 cm ball (metres) stretched to an egg: no symmetry a rotation could hide behind."""
    p, t = sphere(16, 0.01)
    return (p * np.array([1.0, 0.6, 1.4], dtype=np.float32)).astype(np.float32), t


def lit(p, t, sun, point):
    s = translucent.Scene(p, t)
    s.add_sun(tuple(sun), 2.0)
    s.add_point_light(tuple(point), 0.5)
    return s


SUN, POINT = np.array([0.0, 1.0, -0.2]), np.array([0.0, 0.03, 0.01])


def turn(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def bent(p, angle):
    """The egg's upper part bent about the X axis through its middle, the angle ramping in with
    height over its upper half (a smooth bend, as a skinned joint gives)."""
    top = p[:, 2].max()
    w = np.clip(p[:, 2] / top, 0.0, 1.0) ** 2
    a = angle * w
    y, z = p[:, 1], p[:, 2]
    out = p.copy()
    out[:, 1] = np.cos(a) * y - np.sin(a) * z
    out[:, 2] = np.sin(a) * y + np.cos(a) * z
    return out.astype(np.float32)


@pytest.fixture(scope="module")
def rest():
    p, t = egg()
    return p, t, translucent.Prt(lit(p, t, SUN, POINT), SKIN, backend="cpu", walk_rays=RAYS)


@pytest.mark.parametrize("first_preview", [True, False])
def test_a_rigid_motion_with_its_lights_keeps_the_preview(rest, first_preview):
    """Turned by 70 degrees with its lights, the egg sends out what it did: the posed preview
    is the rest pose's, vertex by vertex, within its error estimate (the walks carried are the
    same walks, so their noise does not enter)."""
    p, t, prt = rest
    before = prt.radiance(SKIN)
    r = turn(math.radians(70.0))
    posed = translucent.Prt(lit(p, t, SUN, POINT), SKIN, backend="cpu", walk_rays=RAYS)
    report = posed.update(lights=lit((p @ r.T).astype(np.float32), t, r @ SUN, r @ POINT), first_preview=first_preview)
    assert report["posed"] and report["walks_traced"] == 0 and report["own_light_rays"] == 0
    after = posed.radiance(SKIN)
    w = translucent.Scene(p, t).vertex_areas
    err = np.asarray(translucent.relative_error(after, before, w)["rms"])
    estimate = np.asarray(posed.last_eval["error_estimate"])
    assert np.all(err <= np.maximum(estimate, 0.01)), (err, estimate)
    assert posed.report["carried_pose"] and not prt.report["carried_pose"]
    assert any("carried" in s["why"] for s in posed.last_eval["skipped"])


def test_a_bend_is_nearly_as_close_to_the_walk_reference_as_a_fresh_precompute(rest):
    """The egg's top bent by 20 degrees: the carried preview against Cycles' walk traced inside
    the bent mesh (direct light with direct light), beside a fresh precompute on the bent mesh,
    the half-space profile alone and the rest pose's preview left as it was. The walks are
    carried, not traced on the bend: where the bend lies within their reach (here the whole
    1 cm egg in skin) they are off by what it changed (measured: 3.8 % against the fresh
    2.1 %, red; 5.9 % against 1.9 % at 40 degrees; docs/walks.md, "Poses")."""
    p, t, _ = rest
    q = bent(p, math.radians(20.0))
    scene = lit(q, t, SUN, POINT)
    prt = translucent.Prt(lit(p, t, SUN, POINT), SKIN, backend="cpu", walk_rays=RAYS)
    before = prt.radiosity(SKIN, interreflection=False)
    prt.update(positions=q)
    fresh = translucent.Prt(scene, SKIN, backend="cpu", walk_rays=RAYS)
    receivers = list(range(0, scene.vertex_count, 5))
    truth = translucent.reference_radiance(scene, SKIN, walks=512, receivers=receivers, tunnel=True)
    w = scene.vertex_areas[receivers]
    k = translucent.layer_weight(SKIN.roughness, 1.0, SKIN.eta) / math.pi

    def err(b):
        return max(translucent.relative_error(b[receivers] * k, truth, w)["rms"])

    carried = err(prt.radiosity(SKIN, interreflection=False))
    walked = err(fresh.radiosity(SKIN, interreflection=False))
    halfspace = err(prt.radiosity(SKIN, interreflection=False, walks=False))
    stale = err(before)
    assert carried <= walked + 0.025, f"carried {carried:.4f} vs fresh {walked:.4f}"
    assert carried < 0.5 * halfspace, f"carried {carried:.4f} vs the half-space alone {halfspace:.4f}"
    assert carried < 0.25 * stale, f"carried {carried:.4f} vs the rest pose's {stale:.4f}"


def test_a_pose_refuses_what_is_not_a_pose_and_a_cancel_keeps_the_old_transport(rest):
    p, t, _ = rest
    prt = translucent.Prt(lit(p, t, SUN, POINT), SKIN, backend="cpu", walk_rays=300_000)
    before = prt.radiance(SKIN)
    with pytest.raises(ValueError, match="positions"):
        prt.update(positions=p[:-1])
    with pytest.raises(ValueError, match="normals need positions"):
        prt.update(normals=np.ones_like(p))
    with pytest.raises(ValueError, match="lights .* or positions"):
        prt.update()
    with pytest.raises(ValueError, match="first_preview applies to a pose"):
        prt.update(lights=lit(p, t, -SUN, POINT), first_preview=True)
    bad = p.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN|finite"):
        prt.update(positions=bad)
    # The same count of vertices and triangles, other triangles: not a pose.
    other = lit(p, np.ascontiguousarray(t[:, [1, 2, 0]][::-1]), SUN, POINT)
    with pytest.raises(ValueError, match="topology"):
        prt.update(lights=other)
    with pytest.raises(translucent.Cancelled):
        prt.update(positions=bent(p, 0.5), progress=lambda f: f < 0.5)
    assert np.array_equal(prt.radiance(SKIN), before)
    assert not prt.report["carried_pose"]


def test_a_scene_gives_back_its_positions_and_normals():
    p, t = egg()
    s = translucent.Scene(p, t)
    assert s.positions.shape == (len(p), 3) and s.positions.dtype == np.float32
    np.testing.assert_array_equal(s.positions, p)
    n = s.normals
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, rtol=1e-5)
    # Outward on the egg: the normal points away from its centre.
    assert np.all(np.einsum("ij,ij->i", n, p) > 0.0)


def test_the_hierarchy_with_walks_matches_the_walk_reference_and_carries_them_to_a_pose(rest):
    """`Hierarchy(walks=True)` takes the same walks' term and own light as PRT (the shared
    kernels): at rest as close to Cycles' walk traced inside the egg as PRT, where the
    half-space hierarchy alone is off by the geometry it cannot see; after a 20-degree bend the
    walks carried (no walk traced, under 0.5 s here); `retrace_walks` walks the pose."""
    p, t, prt = rest
    scene = lit(p, t, SUN, POINT)
    receivers = list(range(0, scene.vertex_count, 5))
    k = translucent.layer_weight(SKIN.roughness, 1.0, SKIN.eta) / math.pi

    def err(b, sc):
        truth = translucent.reference_radiance(sc, SKIN, walks=512, receivers=receivers, tunnel=True)
        return max(translucent.relative_error(b[receivers] * k, truth, sc.vertex_areas[receivers])["rms"])

    h = translucent.Hierarchy(scene, SKIN, walks=True, walk_rays=RAYS, mode="render")
    plain = translucent.Hierarchy(scene, SKIN, mode="render")
    walked, halfspace = err(h.radiosity(SKIN), scene), err(plain.radiosity(SKIN), scene)
    own = err(prt.radiosity(SKIN), scene)
    assert walked <= own + 0.01, f"hierarchy with walks {walked:.4f}, PRT {own:.4f}"
    assert walked < 0.5 * halfspace, f"with walks {walked:.4f}, half-space alone {halfspace:.4f}"
    assert h.report["terms"]["walks"]["walks"] > 0 and not h.report["terms"]["carried_pose"]
    assert not any("walks" in s["what"] for s in h.last_eval["skipped"])
    assert any("walks" in s["what"] for s in plain.last_eval["skipped"])
    q = bent(p, math.radians(20.0))
    posed = lit(q, t, SUN, POINT)
    h.update(positions=q)
    carried_b = h.radiosity(SKIN)
    assert h.report["terms"]["carried_pose"]
    assert any("carried" in s["why"] for s in h.last_eval["skipped"])
    carried = err(carried_b, posed)
    h.retrace_walks()
    retraced = err(h.radiosity(SKIN), posed)
    assert not h.report["terms"]["carried_pose"]
    assert retraced <= carried + 0.005 and retraced < 0.03, (retraced, carried)
    plain.update(positions=q)
    assert carried < 0.5 * err(plain.radiosity(SKIN), posed), "carried walks no better than none"


def test_the_hierarchys_walks_refuse_the_dipole_and_a_budget_without_walks():
    p, t = egg()
    scene = lit(p, t, SUN, POINT)
    with pytest.raises(ValueError, match="cycles"):
        translucent.Hierarchy(scene, SKIN, profile="dipole", walks=True)
    with pytest.raises(ValueError, match="walk_rays"):
        translucent.Hierarchy(scene, SKIN, walk_rays=1000)
    with pytest.raises(ValueError, match="walk_rays"):
        translucent.Hierarchy(scene, SKIN, walks=True, walk_rays=-5)
