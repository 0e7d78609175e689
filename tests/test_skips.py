"""Leave out what a scene does not need (issue 5, point 6): each skip is visible in the
precompute's report and costs nothing. Expected values are counts that follow from the scene
set-up (how many lights can reach the mesh, how many shadow rays a point light costs)."""

import numpy as np

import translucent
from helpers import plane

MARBLE = translucent.Material.preset("marble", mm_per_unit=1000.0)


def scene_with(lights=(), world=None, n=21, size=0.2):
    p, t = plane(n, size)
    s = translucent.Scene(p, t)
    for kind, args in lights:
        getattr(s, kind)(**args)
    if world is not None:
        s.set_world(color=world)
    return s


def precompute(scene, **kw):
    kw.setdefault("samples", 5000)
    return translucent.Prt(scene, MARBLE, backend="cpu", **kw)


SUN = ("add_sun", dict(direction=(0, 0, -1), irradiance=1.0))


def test_black_world_costs_no_environment_rays():
    black = precompute(scene_with([SUN])).report
    lit = precompute(scene_with([SUN], world=(0.2, 0.2, 0.2)), world_samples=16).report
    assert black["world_skipped"] and not lit["world_skipped"]
    # A sun above a plane: one shadow ray per point (samples and vertices); the world adds
    # 16 per receiver vertex and, per sample, 16 / 8 = 2 rounded up to a full stratified
    # 2 x 2 grid (the dense estimate).
    points = black["samples"] + black["vertices"]
    assert black["rays"] == points
    assert lit["rays"] == points + 16 * lit["vertices"] + 4 * lit["samples"]


def test_a_light_that_reaches_nothing_costs_nothing():
    away = ("add_spot_light", dict(position=(0, 0, 1.0), direction=(0, 0, 1), power=100.0, spot_size=0.5))
    below = ("add_area_light", dict(position=(0, 0, -0.5), direction=(0, 0, -1), axis_u=(1, 0, 0),
                                    size_u=0.1, size_v=0.1, power=50.0))
    r = precompute(scene_with([SUN, away, below])).report
    assert r["lights_unreached"] == 2 and r["lights_used"] == 1
    assert r["rays"] == r["samples"] + r["vertices"]  # the sun's rays only
    dark = ("add_point_light", dict(position=(0, 0, 1.0), power=0.0))
    r = precompute(scene_with([SUN, dark])).report
    assert r["lights_skipped_black"] == 1 and r["lights_used"] == 1


def test_white_light_needs_one_transport_and_coloured_light_three():
    white = precompute(scene_with([SUN])).report
    red = ("add_point_light", dict(position=(0.05, 0, 0.3), power=20.0, color=(1.0, 0.2, 0.1)))
    coloured = precompute(scene_with([SUN, red])).report
    assert white["stored_channels"] == 1 and coloured["stored_channels"] == 3
    assert coloured["transport_bytes"] > 2.5 * white["transport_bytes"]


def test_support_radius_is_cut_by_the_tolerance():
    # Ketchup (1/sigma_tr ~ 4 mm at its bluest) on a 1 m plane: R_d falls below the tolerance
    # long before the far side, so far clusters are skipped and the support is < the diagonal.
    ketchup = translucent.Material.preset("ketchup", mm_per_unit=1000.0)
    s = scene_with([SUN], n=41, size=1.0)
    prt = translucent.Prt(s, ketchup, samples=20000, backend="cpu")
    r = prt.report
    assert r["support_radius"] < 0.2 * np.sqrt(2.0)
    assert r["skipped_beyond_support"] > 0
    loose = translucent.Prt(s, ketchup, samples=20000, backend="cpu", tolerance=1e-2).report
    assert loose["support_radius"] < r["support_radius"]


def test_basis_size_is_chosen_by_error_when_asked():
    s = scene_with([SUN])
    fixed = precompute(s, coefficients=64).report
    loose = precompute(s, coefficients=64, fit_tolerance=0.05).report
    tight = precompute(s, coefficients=64, fit_tolerance=0.005).report
    assert not fixed["basis_size_by_tolerance"] and fixed["coefficients"] == 64
    assert loose["basis_size_by_tolerance"] and loose["representative_error"] <= 0.05
    assert loose["coefficients"] < tight["coefficients"] <= 64
    assert tight["representative_error"] <= 0.005


def test_no_single_scattering_work():
    assert precompute(scene_with([SUN])).report["single_scattering"] is False
