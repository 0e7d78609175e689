"""One contract for every method (issue 28): PRT and the hierarchy give the same evaluation in
`last_eval` (method, quantity, error estimate per channel, seconds, what was skipped and why),
the hierarchy never reports an estimate it did not compute, and radiance from radiosity is the
same closed form for both (the dipole's exit weight along the normal is Fresnel's
transmittance, 1 - ((eta - 1) / (eta + 1))^2, over pi)."""

import math

import numpy as np
import pytest

import translucent
from helpers import sphere

SHARED = {"method", "quantity", "error_estimate", "seconds", "skipped", "refresh_advised"}


def scene():
    p, t = sphere(12, radius=0.01)
    s = translucent.Scene(p, t)
    s.add_sun(direction=(0.3, 0.4, -0.85), irradiance=1.0)
    return s


def marble():
    return translucent.Material.preset("marble", mm_per_unit=1000.0)


def check_shared(e, method, quantity):
    assert SHARED <= set(e), f"missing {SHARED - set(e)}"
    assert e["method"] == method
    assert e["quantity"] == quantity
    assert e["seconds"] > 0.0
    for s in e["skipped"]:
        assert set(s) == {"what", "why"} and s["what"] and s["why"]


def test_prt_and_hierarchy_share_the_evaluation_keys():
    s, m = scene(), marble()
    prt = translucent.Prt(s, [m], profile="dipole")
    prt.radiance(m)
    check_shared(prt.last_eval, "prt", "radiance")
    prt.radiosity(m)
    check_shared(prt.last_eval, "prt", "radiosity")
    assert len(prt.last_eval["error_estimate"]) == 3
    # The dipole has no walks: that is said, not hidden.
    assert any("walks" in x["what"] for x in prt.last_eval["skipped"])

    h = translucent.Hierarchy(s, m, profile="dipole")
    h.radiance(m)
    check_shared(h.last_eval, "hierarchy", "radiance")
    est = h.last_eval["error_estimate"]
    assert len(est) == 3 and all(math.isfinite(x) and x >= 0.0 for x in est)
    assert h.report["method"] == "hierarchy"
    assert h.report["error_estimate"] == est


def test_the_hierarchy_without_estimate_receivers_reports_no_estimate():
    s, m = scene(), marble()
    h = translucent.Hierarchy(s, m, profile="dipole", estimate_receivers=0)
    h.radiosity(m)
    assert h.last_eval["error_estimate"] is None
    assert h.report["error_estimate"] is None
    assert any(x["what"] == "error estimate" for x in h.last_eval["skipped"])


@pytest.mark.parametrize("method", ["prt", "hierarchy"])
def test_radiance_along_the_normal_is_fresnel_transmittance_over_pi(method):
    s, m = scene(), marble()
    # Multiple scattering alone: single scattering (the dipole's L^(1)) is not radiosity's.
    ev = translucent.Prt(s, [m], profile="dipole", single_scattering=False) if method == "prt" else translucent.Hierarchy(s, m, profile="dipole")
    b = ev.radiosity(m).astype(np.float64)
    lo = ev.radiance(m).astype(np.float64)
    eta = m.eta
    ft = 1.0 - ((eta - 1.0) / (eta + 1.0)) ** 2
    lit = b > 1e-3 * b.max()
    np.testing.assert_allclose(lo[lit], (b * ft / math.pi)[lit], rtol=1e-5)


@pytest.mark.parametrize("method", ["prt", "hierarchy"])
def test_an_eye_far_beyond_the_mesh_sees_what_an_eye_at_infinity_would(method):
    # The direction to an eye 1e14 units away (inside the supported 1e15) is the direction
    # itself: the radiance equals that toward an eye 1e3 units away along the same direction
    # within the parallax (1e-5 rad); beyond 1e15 the eye is refused with a clear error.
    s, m = scene(), marble()
    ev = translucent.Prt(s, [m], profile="dipole") if method == "prt" else translucent.Hierarchy(s, m, profile="dipole")
    d = np.array([0.2, -0.3, 0.93]) / np.linalg.norm([0.2, -0.3, 0.93])
    far = ev.radiance(m, eye=tuple(1e14 * d))
    near = ev.radiance(m, eye=tuple(1e3 * d))
    assert far.max() > 0.0
    np.testing.assert_allclose(far, near, rtol=1e-3, atol=1e-6 * near.max())
    with pytest.raises(ValueError, match="eye"):
        ev.radiance(m, eye=tuple(1e19 * d))
