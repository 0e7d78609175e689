"""The panel shows each method's own evaluation, in headless Blender (issue 28, point 2): with
Method = Hierarchy its estimate line is the hierarchy's own `last_eval` estimate (the same a
`translucent.Hierarchy` built on the exported scene gives), never made-up zeros; where the
hierarchy computes no estimate (estimate_receivers=0) the panel says so and shows no number;
what its evaluation left out is said;
with PRT the line is PRT's own estimate."""

import re

import numpy as np
import pytest

from helpers import draw_panel, lit_sphere

pytestmark = pytest.mark.bpy


def percent(estimate) -> str:
    """An estimate per channel as the panel's user reads it: per cent, three significant digits."""
    return "est. error " + ", ".join(f"{100 * e:.3g}" for e in estimate) + " %"


def estimate_lines(labels):
    return [t for t in labels if "est. error" in t]


def test_the_hierarchy_panel_line_is_the_hierarchys_own_estimate(addon):
    import bpy

    import translucent
    from addon import export, jobs, panel, session

    mat, obj, _ = lit_sphere(bpy, method="HIERARCHY")
    sess = session.SESSIONS[mat.name]
    assert sess.method == "hierarchy" and isinstance(sess.transport, translucent.Hierarchy)
    own = sess.transport.last_eval
    assert own["method"] == "hierarchy" and own["error_estimate"] is not None
    # The same estimate as the API's hierarchy for the exported scene, built apart from the add-on.
    s = mat.translucent
    scene, _ = export.export_scene([obj])
    h = translucent.Hierarchy(scene, s.material(), profile=s.profile_name(), eps=jobs.HIERARCHY_EPS,
                              mode="on_the_fly", world_shadows=True, walks=s.profile_name() == "cycles")
    h.radiance(s.material(), None)
    # With Cycles' profile the walks' noise is part of it.
    assert h.report["terms"] is not None
    np.testing.assert_allclose(own["error_estimate"], h.last_eval["error_estimate"], rtol=1e-6)
    assert max(own["error_estimate"]) > 0, "a real estimate, not the zeros the panel used to show"
    lines = estimate_lines([t for t, _ in panel.status_lines(mat)])
    assert len(lines) == 1 and percent(own["error_estimate"]) in lines[0]
    # What draw() shows is what status_lines gives.
    drawn = estimate_lines(draw_panel(addon, mat))
    assert len(drawn) == 1 and percent(own["error_estimate"]) in drawn[0]
    assert "est. error 0, 0, 0 %" not in drawn[0] and "0.00, 0.00, 0.00" not in drawn[0]
    # What the hierarchy's evaluation left out is said, in its own words.
    labels = draw_panel(addon, mat)
    said = sorted(t for t in labels if t.startswith("Left out:"))
    assert said == sorted(f"Left out: {k['what']} ({k['why']})" for k in own["skipped"]), said


def test_a_hierarchy_without_an_estimate_shows_no_number(addon, monkeypatch):
    import bpy

    from addon import jobs, session

    monkeypatch.setattr(jobs, "HIERARCHY_ESTIMATE_RECEIVERS", 0)
    mat, obj, _ = lit_sphere(bpy, method="HIERARCHY")
    sess = session.SESSIONS[mat.name]
    assert sess.method == "hierarchy" and sess.transport.last_eval["error_estimate"] is None
    assert sess.last_error is None
    drawn = estimate_lines(draw_panel(addon, mat))
    assert len(drawn) == 1 and "est. error: not computed" in drawn[0]
    assert not re.search(r"est\. error [0-9]", drawn[0]) and "%" not in drawn[0]


def test_the_prt_panel_line_is_prts_own_estimate(addon):
    import bpy

    from addon import session

    mat, obj, _ = lit_sphere(bpy, method="PRT")
    sess = session.SESSIONS[mat.name]
    own = sess.transport.last_eval
    assert own["method"] == "prt" and sess.method == "prt"
    drawn = estimate_lines(draw_panel(addon, mat))
    assert len(drawn) == 1 and percent(own["error_estimate"]) in drawn[0]
