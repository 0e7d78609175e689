"""Image-space splatting (Shah et al. 2009, issue 31) through the Python API: nothing
precomputed, every evaluation a fresh splat of each light's view. Expected values: the dipole's
half-plane integral of its closed-form disc integral (helpers.half_plane) under a blocker's
straight shadow edge, the plane's closed total, and the ground truth (`reference_radiosity`, a
brute-force integration of the same profile) on a sphere."""

import math

import numpy as np
import pytest

import translucent
from helpers import assert_shadow_edge, centre_index, entering, plane, rd_total, sphere, square, sun_plane

MARBLE_M = translucent.Material.preset("marble", mm_per_unit=1000.0)
MARBLE_MM = translucent.Material.preset("marble", mm_per_unit=1.0)


def test_a_blockers_shadow_edge_meets_the_half_plane_integral():
    # A 40 cm marble plane under a sun straight down; a blocker 5 cm up covers x > 0: B at a
    # distance d from the edge is E_in (R_total - H(d)) on the lit side and E_in H(d) beneath.
    p, t = plane(81, 0.4)
    s = translucent.Scene(p, t)
    s.add_sun((0.0, 0.0, -1.0), irradiance=3.0)
    s.add_occluder(*square(0.15, 0.0, 0.05, 0.15), name="blocker")
    m = MARBLE_M
    b, ev = translucent.splat_radiosity(s, m, profile="dipole")
    assert ev["method"] == "splat" and ev["quantity"] == "radiosity" and ev["seconds"] > 0
    light = ev["report"]["lights"][0]
    assert light["kind"] == "sun" and light["shadowed"] > 0.3 * light["hits"]  # 20 x 30 of 40 x 40 cm
    assert assert_shadow_edge(b, p, m, entering(m.eta, 1.0, 3.0)) > 100


def test_the_plane_gives_the_closed_total_and_the_sphere_the_ground_truth():
    p, s = sun_plane(81, 200.0)  # millimetres
    v = centre_index(p)
    expect = np.array([entering(MARBLE_MM.eta, 1.0) * rd_total(MARBLE_MM.sigma_a[c], MARBLE_MM.sigma_s[c], MARBLE_MM.eta)
                       for c in range(3)])
    # Eq. 4 cuts each splat at r_max, leaving up to eps of its light beyond: the default eps
    # 0.01 gives up to 1 % less; a smaller eps gives it back.
    for eps, lo, hi in [(0.01, 0.985, 1.001), (1e-4, 0.997, 1.003)]:
        b, ev = translucent.splat_radiosity(s, MARBLE_MM, profile="dipole", eps=eps)
        assert np.all(b[v] / expect > lo) and np.all(b[v] / expect < hi), (eps, b[v] / expect)

    p, t = sphere(16, 10.0)
    s = translucent.Scene(p, t)
    s.add_sun((0.3, 0.2, -1.0), 1.0)
    b, ev = translucent.splat_radiosity(s, MARBLE_MM, profile="dipole")
    idx = list(range(0, len(p), len(p) // 24))
    truth = translucent.reference_radiosity(s, MARBLE_MM, rel_tol=3e-3, receivers=idx, profile="dipole")
    err = translucent.relative_error(b[idx], truth, s.vertex_areas[idx, 0])
    assert max(err["rms"]) < 0.02, err
    assert ev["error_estimate"] is None  # none computed: said, not invented
    # Any profile: the multipole of 1.5 mm of skin over marble against its own ground truth.
    layered = MARBLE_MM.with_stack(top=translucent.Material.preset("skin1", mm_per_unit=1.0), top_thickness=1.5)
    truth_l = translucent.reference_radiosity(s, layered, rel_tol=3e-3, receivers=idx, profile="multipole")
    b_l, _ = translucent.splat_radiosity(s, layered, profile="multipole")
    err = translucent.relative_error(b_l[idx], truth_l, s.vertex_areas[idx, 0])
    assert max(err["rms"]) < 0.02, err
    assert {"walks through the mesh", "error estimate"} <= {x["what"] for x in ev["skipped"]}
    # The radiance is B through the profile's exit weight: along the normal, W(1) B / pi.
    l, ev = translucent.splat_radiance(s, MARBLE_MM, profile="dipole")
    assert ev["quantity"] == "radiance"
    lit = b > 1e-3
    ratio = l[lit] * math.pi / b[lit]
    assert lit.sum() > 100 and np.ptp(ratio) < 1e-4 and 0.5 < ratio.mean() < 1.0


def test_what_it_cannot_splat_is_named_and_bad_arguments_raise():
    p, s = sun_plane(21, 20.0)
    s.add_area_light((0.0, 0.0, 5.0), (0.0, 0.0, -1.0), (1.0, 0.0, 0.0), 1.0, 1.0, 10.0)
    _, ev = translucent.splat_radiosity(s, MARBLE_MM, profile="dipole", max_grid=128)
    area = [x for x in ev["skipped"] if x["what"].startswith("light 1")]
    assert len(area) == 1 and "area" in area[0]["what"], ev["skipped"]
    assert ev["report"]["lights"][0]["grid"] == 128 and ev["report"]["lights"][0]["grid_capped"]
    for kw, name in [({"eps": 0.0}, "eps"), ({"eps": float("nan")}, "eps"), ({"max_grid": 0}, "max_grid"),
                     ({"max_grid": 10**6}, "max_grid"), ({"max_grid": -1}, "max_grid"), ({"profile": "x"}, "profile")]:
        with pytest.raises(ValueError, match=name):
            translucent.splat_radiosity(s, MARBLE_MM, **kw)
    with pytest.raises(translucent.Cancelled):
        translucent.splat_radiosity(s, MARBLE_MM, profile="dipole", progress=lambda f: False)
