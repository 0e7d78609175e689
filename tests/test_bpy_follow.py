"""The add-on follows the scene (issue 10, point 5), in headless Blender: a deformed mesh (a
Displace modifier, an armature pose, a shape key, an Edit Mode edit, an animated modifier on
the timeline), a moved light and an object taking the material refresh the preview without
pressing anything; the add-on's own colour writes are not taken for a deformation; a
topology change rebuilds; with a UI the refresh runs on a worker thread and the old preview
stays until it is done; the panel's draw evaluates no mesh; the Method selector falls back to
PRT, saying why, in a build without the hierarchy; the user's meshes and materials are
never written.

Headless Blender runs no timers: the tests let the real depsgraph handlers fire
(`view_layer.update()`, `frame_set`) and then do what the debounced timer does once the scene
is still (`follow.follow_now`). The expected preview after following is the one pressing
Precompute gives for the changed scene (a light change relights the transport instead: equal
to it within the walks' stated noise)."""

import ast
import pathlib
import time

import numpy as np
import pytest

import translucent

from helpers import draw_panel, key_light, lit_sphere, mesh_hash, read_preview

pytestmark = pytest.mark.bpy

ADDON = pathlib.Path(__file__).resolve().parents[1] / "addon"


def node_inputs(mat):
    return [(n.name, i.identifier, tuple(i.default_value) if hasattr(i.default_value, "__len__") else i.default_value)
            for n in mat.node_tree.nodes for i in n.inputs if hasattr(i, "default_value")]


def precomputed_preview(bpy, mat, obj):
    """What pressing Precompute shows for the scene as it is now."""
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    return read_preview(obj)


def relit_like_a_precompute(bpy, session, mat, obj):
    """The preview after a light change (the transport relit, no walk traced) against pressing
    Precompute for the changed scene: the relit walks' term and a fresh one differ by the
    walks' noise, which both estimates state. Returns the fresh preview."""
    relit = session.SESSIONS[mat.name]
    assert relit.follow_message.startswith("relit:") and " 0 walks traced" in relit.follow_message
    relit_estimate = np.asarray(relit.transport.last_eval["error_estimate"])
    now = read_preview(obj)
    fresh = precomputed_preview(bpy, mat, obj)
    fresh_estimate = np.asarray(session.SESSIONS[mat.name].transport.last_eval["error_estimate"])
    rel = np.sqrt(np.mean((now - fresh) ** 2, axis=0) / np.mean(fresh**2, axis=0))
    assert np.all(rel <= 2.0 * (relit_estimate + fresh_estimate)), (rel, relit_estimate, fresh_estimate)
    return fresh


def test_a_deformed_mesh_refreshes_the_preview_after_the_scene_is_still(addon, monkeypatch):
    import bpy

    from addon import follow, session

    mat, obj, light = lit_sphere(bpy)
    user_mesh, user_nodes = mesh_hash(obj.data), node_inputs(mat)
    first, sess = read_preview(obj), session.SESSIONS[mat.name]
    clock = [100.0]
    monkeypatch.setattr(follow, "_clock", lambda: clock[0])
    obj.modifiers["Displace"].strength = 0.02  # the sphere grows by 1 cm: nearer the light
    bpy.context.view_layer.update()  # the depsgraph handler notes it, evaluates nothing
    assert mat.name in follow.PENDING and bpy.app.timers.is_registered(follow.follow_tick)
    # Debounced: while the scene keeps changing, the timer waits and the old preview stays.
    assert follow.follow_tick() == pytest.approx(follow.DEBOUNCE_S)
    assert session.SESSIONS[mat.name] is sess
    np.testing.assert_array_equal(read_preview(obj), first)
    clock[0] += 1.0  # still for longer than DEBOUNCE_S
    follow.follow_tick()
    followed = session.SESSIONS[mat.name]
    assert followed is not sess and session.state(mat) == "ready" and not followed.changed
    # What may be left pending is the add-on's own colour writes (the pose carried, then
    # refined: two): checked, no second refresh.
    for _ in range(2):
        clock[0] += 1.0
        if follow.follow_tick() is None:
            break
    assert follow.follow_tick() is None
    assert session.SESSIONS[mat.name] is followed and not follow.PENDING
    now = read_preview(obj)
    assert not np.allclose(now, first), "the deformation did not change the preview"
    np.testing.assert_allclose(now, precomputed_preview(bpy, mat, obj), rtol=1e-5, atol=1e-7)
    assert mesh_hash(obj.data) == user_mesh and node_inputs(mat) == user_nodes
    assert [m.name for m in obj.modifiers] == ["Displace"] and obj.modifiers["Displace"].strength == pytest.approx(0.02)


def test_an_armature_pose_refreshes_the_preview(addon):
    import bpy

    from addon import follow, session

    mat, obj, _ = lit_sphere(bpy)
    arm_data = bpy.data.armatures.new("Rig")
    rig = bpy.data.objects.new("Rig", arm_data)
    bpy.context.scene.collection.objects.link(rig)
    bpy.context.view_layer.objects.active = rig
    bpy.ops.object.mode_set(mode="EDIT")
    bone = arm_data.edit_bones.new("Bone")
    bone.head, bone.tail = (0.0, 0.0, 0.0), (0.0, 0.0, 0.05)
    bpy.ops.object.mode_set(mode="OBJECT")
    group = obj.vertex_groups.new(name="Bone")
    upper = [v.index for v in obj.data.vertices if v.co.z > 0.0]
    group.add(upper, 1.0, "REPLACE")
    obj.modifiers.new("Armature", "ARMATURE").object = rig
    bpy.context.view_layer.objects.active = obj
    user_mesh, user_nodes = mesh_hash(obj.data), node_inputs(mat)
    # Rig and weights in place, rest pose: the evaluated mesh has not moved.
    bpy.context.view_layer.update()
    follow.follow_now()
    rest = session.SESSIONS[mat.name]
    assert session.state(mat) == "ready" and not rest.deformed
    first = read_preview(obj)
    # The pose is shown twice: carried at once ("posed (refining)"), then refined.
    import translucent
    from addon import edits

    shown = []
    show_first = edits.show_first

    def recording(material, job, *args):
        out = show_first(material, job, *args)
        shown.append((session.SESSIONS[material.name].method_message, read_preview(obj),
                      session.SESSIONS[material.name].transport.report["carried_pose"]))
        return out

    edits.show_first = recording
    try:
        rig.pose.bones["Bone"].location = (0.0, 0.03, 0.0)  # the upper half slides toward +Y
        bpy.context.view_layer.update()
        assert mat.name in follow.PENDING
        follow.follow_now()
    finally:
        edits.show_first = show_first
    assert session.SESSIONS[mat.name] is not rest and session.state(mat) == "ready"
    refined = session.SESSIONS[mat.name]
    assert refined.follow_message.startswith("refined"), refined.follow_message
    assert not refined.transport.report["carried_pose"]
    now = read_preview(obj)
    assert not np.allclose(now, first), "the pose did not change the preview"
    np.testing.assert_allclose(now, precomputed_preview(bpy, mat, obj), rtol=1e-5, atol=1e-7)
    assert len(shown) == 1, shown
    message, carried, was_carried = shown[0]
    assert message.startswith("posed (refining)") and was_carried, message
    # The carried preview is the refined one within both estimates, and far from the rest pose's.
    w = np.ones(len(now))
    between = max(translucent.relative_error(carried, now, w[:, None])["rms"])
    moved = max(translucent.relative_error(first, now, w[:, None])["rms"])
    assert between < 0.5 * moved, (between, moved)
    assert mesh_hash(obj.data) == user_mesh and node_inputs(mat) == user_nodes


def test_a_moved_light_refreshes_the_preview_and_the_panel_says_why_meanwhile(addon):
    import bpy

    from addon import follow, session

    mat, obj, light = lit_sphere(bpy)
    first, user_mesh = read_preview(obj), mesh_hash(obj.data)
    light.location.x += 0.1
    bpy.context.view_layer.update()
    assert session.state(mat) == "stale" and session.SESSIONS[mat.name].changed == "light Key changed"
    np.testing.assert_array_equal(read_preview(obj), first)  # kept until the new one is ready
    follow.follow_now()
    assert session.state(mat) == "ready"
    assert not np.allclose(read_preview(obj), first)
    # Only the light changed: the transport was relit (Prt.update), no walk traced again.
    fresh = relit_like_a_precompute(bpy, session, mat, obj)
    # The light's power is followed as well (light data, not only the object): twice the
    # power, twice the light, exactly (everything the update recomputes is linear in it).
    light.data.energy = 10.0
    bpy.context.view_layer.update()
    assert session.SESSIONS[mat.name].changed == "light Key changed"
    follow.follow_now()
    np.testing.assert_allclose(read_preview(obj), 2.0 * fresh, rtol=1e-4, atol=1e-7)
    # A second light, then the first one's power alone: the transport is the old one plus the
    # key light's own layer (`light_layer`), relit at the first such change and kept for the
    # next; the preview is what Precompute shows for the scene then.
    key_light(bpy, location=(0.15, 0.0, 0.1), energy=3.0)
    bpy.context.view_layer.update()
    follow.follow_now()
    for energy, summed in ((6.0, True), (8.0, False)):
        light.data.energy = energy
        bpy.context.view_layer.update()
        follow.follow_now()
        message = session.SESSIONS[mat.name].follow_message
        assert "the light's layer" in message and ("relit in" in message) == summed, message
    relit_like_a_precompute(bpy, session, mat, obj)
    assert mesh_hash(obj.data) == user_mesh


def test_scrubbing_the_timeline_follows_an_animated_modifier(addon):
    import bpy

    from addon import follow, session

    mat, obj, _ = lit_sphere(bpy)
    displace = obj.modifiers["Displace"]
    displace.keyframe_insert("strength", frame=1)
    displace.strength = 0.02
    displace.keyframe_insert("strength", frame=10)
    bpy.context.scene.frame_set(1)
    follow.follow_now()
    assert session.state(mat) == "ready"
    first = read_preview(obj)
    bpy.context.scene.frame_set(10)  # frame_change_post
    assert mat.name in follow.PENDING
    follow.follow_now()
    now = read_preview(obj)
    assert not np.allclose(now, first)
    np.testing.assert_allclose(now, precomputed_preview(bpy, mat, obj), rtol=1e-5, atol=1e-7)


def test_the_addons_own_colour_writes_are_not_a_deformation(addon):
    """Writing the preview attribute tags the mesh's geometry like a deformation does: the
    check tells them apart by the evaluated positions, so an edit never starts a refresh."""
    import bpy

    from addon import follow, session

    mat, obj, _ = lit_sphere(bpy)
    sess = session.SESSIONS[mat.name]
    mat.translucent.auto_refresh = False  # only following the scene may refresh here
    first = read_preview(obj)
    mat.translucent.sigma_a = tuple(2.0 * x for x in mat.translucent.sigma_a)  # a slider edit: a colour write
    assert not np.allclose(read_preview(obj), first)
    bpy.context.view_layer.update()
    assert mat.name in follow.PENDING, "the write tagged the mesh"
    follow.follow_now()
    assert session.SESSIONS[mat.name] is sess and session.state(mat) == "ready" and not sess.deformed


def test_a_topology_change_rebuilds_and_shows_through_the_original_vertices(addon):
    import bpy

    from addon import follow, session

    mat, obj, _ = lit_sphere(bpy)
    n = len(obj.data.vertices)
    obj.modifiers.new("Subdivision", "SUBSURF").levels = 1
    bpy.context.view_layer.update()
    follow.follow_now()
    sess = session.SESSIONS[mat.name]
    assert sess.info.objects[0].count > n, "rebuilt for the subdivided mesh"
    assert sess.not_shown == [] and len(read_preview(obj)) == n
    assert session.state(mat) == "ready"


def test_without_following_the_panel_says_stale_and_nothing_refreshes(addon):
    import bpy

    from addon import follow, session

    mat, obj, light = lit_sphere(bpy)
    mat.translucent.follow_scene = False
    sess = session.SESSIONS[mat.name]
    obj.modifiers["Displace"].strength = 0.02
    bpy.context.view_layer.update()
    follow.follow_now()
    assert session.SESSIONS[mat.name] is sess
    assert session.state(mat) == "stale" and sess.changed == f"{obj.name} deformed"
    obj.modifiers["Displace"].strength = 0.0  # back as it was: current again
    bpy.context.view_layer.update()
    follow.follow_now()
    assert session.state(mat) == "ready"
    # Switched back on, it catches up with what changed while it was off.
    light.location.z += 0.05
    bpy.context.view_layer.update()
    follow.follow_now()
    assert session.SESSIONS[mat.name] is sess and session.state(mat) == "stale"
    mat.translucent.follow_scene = True
    follow.follow_now()
    assert session.SESSIONS[mat.name] is not sess and session.state(mat) == "ready"


def test_the_panel_draw_evaluates_no_mesh(addon, monkeypatch):
    import bpy

    from addon import export, follow

    # The add-on evaluates meshes in two functions only (checked here from its source: the
    # export's and the Base Color bake's copy), so counting their calls counts every evaluation.
    callers = set()
    for path in ADDON.glob("*.py"):
        for fn in ast.walk(ast.parse(path.read_text())):
            if isinstance(fn, ast.FunctionDef):
                for node in ast.walk(fn):
                    if isinstance(node, ast.Attribute) and node.attr in {"evaluated_get", "to_mesh"}:
                        callers.add(f"{path.stem}.{fn.name}")
    assert callers == {"export._evaluate", "export.evaluated_copy"}
    calls = []
    original, copy = export._evaluate, export.evaluated_copy
    monkeypatch.setattr(export, "_evaluate", lambda *a, **k: (calls.append(a[0].name), original(*a, **k))[1])
    monkeypatch.setattr(export, "evaluated_copy", lambda *a, **k: (calls.append(a[0].name), copy(*a, **k))[1])

    mat = bpy.data.materials.new("Wax")
    mat.translucent.enabled = True
    assert any("press Precompute" in t for t in draw_panel(addon, mat))
    mat, obj, light = lit_sphere(bpy)
    calls.clear()
    assert "Changed" not in " ".join(draw_panel(addon, mat))
    obj.modifiers["Displace"].strength = 0.02
    light.location.x += 0.1
    bpy.context.view_layer.update()
    labels = draw_panel(addon, mat)
    assert calls == [], "a redraw evaluated a mesh"
    assert "Changed: light Key changed (refreshing)" in labels
    # The counting is live: the follow check evaluates, and the panel then shows what it found.
    mat.translucent.follow_scene = False
    follow.follow_now()
    assert calls == [obj.name]
    calls.clear()
    assert f"Changed: {obj.name} deformed, light Key changed" in draw_panel(addon, mat)
    assert calls == []


def test_the_hierarchy_method_falls_back_to_prt_saying_why(addon, monkeypatch):
    import bpy

    import translucent
    from addon import follow, jobs, session

    monkeypatch.delattr(translucent, "Hierarchy", raising=False)
    mat, obj, light = lit_sphere(bpy, method="HIERARCHY")
    sess = session.SESSIONS[mat.name]
    assert sess.method == "prt" and sess.method_message == jobs.HIERARCHY_MISSING
    assert jobs.HIERARCHY_MISSING in draw_panel(addon, mat)
    mat.translucent.method = "AUTO"
    obj.modifiers["Displace"].strength = 0.02
    bpy.context.view_layer.update()
    follow.follow_now()
    # Auto with PRT holding the transport: the pose carried by PRT, nothing missed.
    sess = session.SESSIONS[mat.name]
    assert sess.method == "prt" and sess.method_message == ""
    assert sess.follow_message.startswith("refined")
    assert session.state(mat) == "ready"


def test_auto_picks_the_method_by_what_changed(addon, monkeypatch):
    import translucent
    from addon import jobs

    monkeypatch.setattr(translucent, "Hierarchy", object, raising=False)
    assert jobs.resolve_method("AUTO", "precompute") == ("prt", "")
    assert jobs.resolve_method("AUTO", "light", "prt") == ("prt", "")
    # A pose: PRT carries its walks to it at once (then traces them on it); the hierarchy updates
    # itself in place where it holds the transport.
    assert jobs.resolve_method("AUTO", "deformation", "prt") == ("prt", "")
    assert jobs.resolve_method("AUTO", "deformation", "hierarchy") == ("hierarchy", "")
    assert jobs.resolve_method("AUTO", "light", "hierarchy") == ("hierarchy", "")
    assert jobs.resolve_method("PRT", "deformation") == ("prt", "")
    assert jobs.resolve_method("HIERARCHY", "precompute") == ("hierarchy", "")
    monkeypatch.delattr(translucent, "Hierarchy")
    assert jobs.resolve_method("HIERARCHY", "precompute") == ("prt", jobs.HIERARCHY_MISSING)
    assert jobs.resolve_method("AUTO", "deformation", "hierarchy") == ("prt", jobs.HIERARCHY_MISSING)


def test_a_shape_key_and_edit_mode_edits_are_followed(addon):
    import bmesh
    import bpy

    from addon import follow, session

    mat, obj, _ = lit_sphere(bpy)
    obj.shape_key_add(name="Basis")
    grow = obj.shape_key_add(name="Grow")
    for point in grow.data:
        point.co *= 1.25
    grow.value = 0.0
    bpy.context.view_layer.update()
    follow.follow_now()
    assert session.state(mat) == "ready"
    first = read_preview(obj)
    grow.value = 1.0
    bpy.context.view_layer.update()
    follow.follow_now()
    shaped = read_preview(obj)
    assert not np.allclose(shaped, first), "the shape key did not change the preview"
    np.testing.assert_allclose(shaped, precomputed_preview(bpy, mat, obj), rtol=1e-5, atol=1e-7)
    # Edit Mode: noticed, but shown when leaving it (a write now would be lost on the way out).
    obj.active_shape_key_index = 0
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    bm = bmesh.from_edit_mesh(obj.data)
    for v in bm.verts:
        if v.co.z > 0.02:
            v.co.y += 0.02
    bmesh.update_edit_mesh(obj.data)
    bpy.context.view_layer.update()
    sess = session.SESSIONS[mat.name]
    follow.follow_now()
    assert session.SESSIONS[mat.name] is sess and "Edit Mode" in sess.follow_message
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.context.view_layer.update()
    follow.follow_now()
    assert session.SESSIONS[mat.name] is not sess and session.state(mat) == "ready"
    edited = read_preview(obj)
    assert not np.allclose(edited, shaped)
    np.testing.assert_allclose(edited, precomputed_preview(bpy, mat, obj), rtol=1e-5, atol=1e-7)


def test_an_object_taking_the_material_is_followed(addon):
    import bpy

    from addon import follow, session

    mat, obj, _ = lit_sphere(bpy)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.03, location=(0.1, 0.0, 0.0), segments=12, ring_count=6)
    other = bpy.context.active_object
    bpy.context.view_layer.update()
    follow.follow_now()
    assert session.state(mat) == "ready" and session.SESSIONS[mat.name].objects == [obj.name]
    other.data.materials.append(mat)
    bpy.context.view_layer.update()
    follow.follow_now()
    sess = session.SESSIONS[mat.name]
    assert sorted(sess.objects) == sorted([obj.name, other.name]) and session.state(mat) == "ready"
    assert read_preview(other).max() > 0


def test_with_a_ui_the_refresh_runs_on_a_worker_and_the_old_preview_stays_until_it_is_done(addon, monkeypatch):
    """The path Blender with a window takes: the precompute on a worker thread, polled by a
    timer (captured here, as headless Blender runs none); the preview swaps only when the
    poll finds the job done."""
    import bpy

    from addon import follow, jobs, session

    mat, obj, light = lit_sphere(bpy)
    first, sess = read_preview(obj), session.SESSIONS[mat.name]
    timers = []
    monkeypatch.setattr(jobs, "headless", lambda: False)
    monkeypatch.setattr(bpy.app.timers, "register", lambda fn, first_interval=0.0, persistent=False: timers.append(fn))
    monkeypatch.setattr(bpy.app.timers, "is_registered", lambda fn: fn in timers)
    light.location.x += 0.1
    bpy.context.view_layer.update()
    follow.follow_now()
    job = session.JOBS[mat.name]
    assert session.state(mat) == "running" and job._thread.ident is not None, "started on a worker thread"
    assert job.background and "Refreshing in the background" in " ".join(draw_panel(addon, mat))
    # Whatever the worker does meanwhile, the artist sees the old preview.
    np.testing.assert_array_equal(read_preview(obj), first)
    assert session.SESSIONS[mat.name] is sess
    job._thread.join(timeout=120)
    poll = next(fn for fn in timers if fn.__name__ == "poll")
    assert poll() is None, "the job is done"
    assert session.SESSIONS[mat.name] is not sess and session.state(mat) == "ready"
    assert not np.allclose(read_preview(obj), first)
    relit_like_a_precompute(bpy, session, mat, obj)


def test_a_hierarchy_edit_runs_on_a_worker_and_the_last_edit_wins(addon, monkeypatch):
    """With a UI, a slider edit of a material the hierarchy previews (which sums its links again:
    seconds on a real mesh) is evaluated on a worker thread: the UI thread returns at once, the
    old preview stays, and the panel draws from the report the last evaluation left (the
    hierarchy says "busy" to any other thread meanwhile). An edit made while one runs cancels
    it, and what is shown in the end is the hierarchy's answer for the last edit."""
    import threading

    import bpy

    from addon import jobs, session

    mat, obj, _ = lit_sphere(bpy, method="HIERARCHY")
    sess = session.SESSIONS[mat.name]
    first = read_preview(obj)
    timers = []
    monkeypatch.setattr(jobs, "headless", lambda: False)
    monkeypatch.setattr(bpy.app.timers, "register", lambda fn, first_interval=0.0, persistent=False: timers.append(fn))
    monkeypatch.setattr(bpy.app.timers, "is_registered", lambda fn: fn in timers)
    # The first job is held at its first progress call (before its work starts) until the
    # second edit has been made.
    gate, tick = threading.Event(), jobs.EditJob._tick

    def held(job, f):
        gate.wait(60)
        return tick(job, f)

    monkeypatch.setattr(jobs.EditJob, "_tick", held)

    def settle():
        while mat.name in session.JOBS:
            session.JOBS[mat.name]._thread.join(timeout=120)
            for poll in [fn for fn in timers if fn.__name__ == "poll"]:
                timers.remove(poll)
                poll()

    s = mat.translucent
    s.sigma_a = (0.02, 0.03, 0.05)
    job = session.JOBS[mat.name]
    assert isinstance(job, jobs.EditJob) and job._thread.ident is not None, "started on a worker thread"
    np.testing.assert_array_equal(read_preview(obj), first)
    transport, sess.transport = sess.transport, None  # the panel must not need it
    lines = " ".join(draw_panel(addon, mat))
    sess.transport = transport
    assert "Evaluating the edit in the background" in lines and "hierarchy (Mertens 2003)" in lines
    s.sigma_a = (0.05, 0.06, 0.08)
    assert job.cancel and session.JOBS[mat.name] is job, "the running edit is told to stop"
    gate.set()
    settle()
    assert isinstance(job.error, translucent.Cancelled), "the overtaken edit stopped"
    assert session.SESSIONS[mat.name] is sess and sess.edit_message == ""
    assert sess.evaluated[0] == (session.params(s), sess.texture_key)
    expected = sess.transport.radiance(s.material())
    np.testing.assert_allclose(read_preview(obj), expected, rtol=1e-5, atol=1e-9)
    assert not np.allclose(read_preview(obj), first)
    # An edit back to a material already shown is evaluated again, as any other.
    s.sigma_a = (0.02, 0.03, 0.05)
    settle()
    np.testing.assert_allclose(read_preview(obj), sess.transport.radiance(s.material()), rtol=1e-5, atol=1e-9)


def test_the_hierarchy_method_previews_and_follows_a_deformation(addon):
    """With `translucent.Hierarchy` built in: Method = Hierarchy previews what the API's
    hierarchy gives for the exported scene (with Cycles' profile, its walks and own light on),
    and a deformation is followed by the hierarchy's own update (same topology): the walks
    carried at once ("posed (refining)"), then walked on the pose ("refined"), as close to
    Cycles' walk traced inside the deformed mesh as a hierarchy built afresh for it."""
    import bpy

    import translucent
    from addon import edits, export, follow, jobs, session

    mat, obj, light = lit_sphere(bpy, method="HIERARCHY")
    sess = session.SESSIONS[mat.name]
    assert sess.method == "hierarchy" and sess.method_message == ""
    s = mat.translucent
    walks = s.profile_name() == "cycles"
    assert walks and sess.transport.report["terms"] is not None

    def fresh():
        scene, _ = export.export_scene([obj])
        h = translucent.Hierarchy(scene, s.material(), profile=s.profile_name(), eps=jobs.HIERARCHY_EPS,
                                  world_shadows=True, estimate_receivers=jobs.HIERARCHY_ESTIMATE_RECEIVERS,
                                  walks=walks)
        return h, scene

    h, _ = fresh()
    first = read_preview(obj)
    np.testing.assert_allclose(first, h.radiance(s.material(), None), rtol=1e-5, atol=1e-8)
    user_mesh = mesh_hash(obj.data)
    messages = []
    finish = edits.finish

    def recording(material, job, *args):
        out = finish(material, job, *args)
        messages.append(out.follow_message)
        return out

    edits.finish = recording
    try:
        obj.modifiers["Displace"].strength = 0.02
        bpy.context.view_layer.update()
        follow.follow_now()
    finally:
        edits.finish = finish
    assert [m.split(":")[0] for m in messages] == ["posed (refining)", "refined"], messages
    followed = session.SESSIONS[mat.name]
    assert followed.method == "hierarchy" and session.state(mat) == "ready"
    assert not followed.transport.report["terms"]["carried_pose"]
    now = read_preview(obj)
    assert not np.allclose(now, first), "the deformation did not change the preview"
    np.testing.assert_allclose(now, followed.transport.radiance(s.material(), None), rtol=1e-6)
    # Against Cycles' walk traced inside the deformed mesh: no further from it than a hierarchy
    # built afresh for the deformed mesh, within a point. (On this coarse sphere, 224 faces of
    # about 1 cm, the hierarchy gathers at face centroids: both are several per cent off; the
    # < 2 % of issue 10 is measured on the bunny and the horse, tests/test_hierarchy.py.)
    h_new, scene = fresh()
    truth = translucent.reference_radiance(scene, s.material(), walks=256)
    w = scene.vertex_areas[:, 0]
    updated = max(translucent.relative_error(now, truth, w)["rms"])
    rebuilt = max(translucent.relative_error(h_new.radiance(s.material(), None), truth, w)["rms"])
    assert updated < rebuilt + 0.01 and rebuilt < 0.1, (updated, rebuilt)
    assert mesh_hash(obj.data) == user_mesh


def test_the_preview_follows_the_view_where_single_scattering_makes_it_depend_on_it(addon):
    """Issue 11: with the dipole (single scattering on) the preview is drawn toward the
    viewport's eye; moving the eye draws it again, an unchanged eye does not, a slider edit draws
    toward the same eye; with Cycles' profile (view independent) the eye changes nothing. The
    timer draws toward the 3D viewport's eye."""
    import bpy

    from addon import edits, follow, session

    mat, obj, light = lit_sphere(bpy)
    assert not follow.set_eye(mat, (0.0, -1.0, 0.3)), "Cycles' profile holds no view dependence"
    mat.translucent.profile = "DIPOLE"
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    sess = session.SESSIONS[mat.name]
    assert sess.transport.report["single_scattering"]
    along = read_preview(obj)
    eye = (0.0, -1.0, 0.3)
    assert follow.set_eye(mat, eye)
    toward = read_preview(obj)
    np.testing.assert_allclose(toward, sess.transport.radiance(mat.translucent.material(), eye), rtol=1e-6)
    assert not np.allclose(toward, along)
    assert not follow.set_eye(mat, eye), "the same eye is not drawn again"
    assert follow.set_eye(mat, (1.0, 0.0, 0.2))
    moved = read_preview(obj)
    assert not np.allclose(moved, toward)
    mat.translucent.preset = "SKIN1"
    edits.edit(mat)
    np.testing.assert_allclose(read_preview(obj), sess.transport.radiance(mat.translucent.material(), (1.0, 0.0, 0.2)),
                               rtol=1e-6)
    # The timer reads the 3D viewport's view (the factory startup has one, headless too).
    eye_view = follow.viewport_eye()
    assert eye_view is not None and follow.follow_view_tick() == follow.VIEW_POLL_S
    assert sess.eye == pytest.approx(eye_view)
    np.testing.assert_allclose(read_preview(obj), sess.transport.radiance(mat.translucent.material(), eye_view), rtol=1e-6)
    assert follow.set_eye(mat, None)
    np.testing.assert_allclose(read_preview(obj), sess.transport.radiance(mat.translucent.material()), rtol=1e-6)


def test_a_prop_added_then_moved_into_the_light_shadows_the_preview_by_itself(addon):
    # Issue 30: another object is an occluder; adding it, and moving it between the key light
    # and the sphere, each refresh the preview by themselves (relit: no walk traced), as
    # pressing Precompute for the changed scene would show it. The prop's mesh is never written.
    import bpy

    from addon import follow, session

    mat, obj, light = lit_sphere(bpy)
    first, user_mesh = read_preview(obj), mesh_hash(obj.data)
    bpy.ops.mesh.primitive_cube_add(size=0.05, location=(0.4, 0.0, 0.0))  # beside: no shadow
    box = bpy.context.active_object
    box_mesh = mesh_hash(box.data)
    bpy.context.view_layer.update()
    assert mat.name in follow.PENDING
    follow.follow_now([mat.name])
    sess = session.SESSIONS[mat.name]
    assert session.state(mat) == "ready" and sess.info.occluders == [box.name]
    assert sess.follow_message.startswith("relit:")
    aside = relit_like_a_precompute(bpy, session, mat, obj)
    # Nothing in the light's way: the lit side as it was; the grey box (Cycles' default surface,
    # albedo 0.8) only sends a little light back, also into the sphere's unlit side.
    lit = first.sum(axis=1) > 0.1 * first.sum(axis=1).max()
    np.testing.assert_allclose(aside[lit], first[lit], rtol=0.05)
    assert np.abs(aside - first).max() < 0.03 * first.max()
    # Between the light (0, -0.15, 0.15) and the sphere, smaller than the sphere seen from the
    # light: the middle of the lit side falls in its shadow, the rim stays lit.
    box.scale = (0.2, 0.2, 0.2)
    box.location = (0.0, -0.1, 0.1)
    bpy.context.view_layer.update()
    follow.follow_now([mat.name])
    assert session.state(mat) == "ready" and session.SESSIONS[mat.name].follow_message.startswith("relit:")
    shadowed = relit_like_a_precompute(bpy, session, mat, obj)
    p = np.array([v.co for v in obj.data.vertices])
    toward = p @ np.array([0.0, -1.0, 1.0]) / (np.sqrt(2.0) * np.linalg.norm(p, axis=1))
    middle = toward > 0.97
    assert middle.sum() >= 1 and np.all(shadowed[middle].sum(axis=1) < 0.2 * aside[middle].sum(axis=1))
    assert shadowed.sum() < 0.8 * aside.sum() and shadowed.max() > 0.5 * aside.max()
    assert mesh_hash(box.data) == box_mesh and mesh_hash(obj.data) == user_mesh


def test_a_moved_prop_is_stale_until_the_check_and_the_panel_says_which(addon):
    import bpy

    from addon import follow, session

    mat, obj, _ = lit_sphere(bpy)
    bpy.ops.mesh.primitive_cube_add(size=0.05, location=(0.4, 0.0, 0.0))
    box = bpy.context.active_object
    mat.translucent.follow_scene = False
    bpy.context.view_layer.update()
    follow.follow_now()
    assert session.SESSIONS[mat.name].changed == f"occluder {box.name} added" and session.state(mat) == "stale"
    assert any(f"occluder {box.name} added" in t for t in draw_panel(addon, mat))


def test_a_dragged_light_is_relit_while_it_moves_and_a_deformation_still_waits(addon, monkeypatch):
    # Issue 29 point 5: a light dragged (a change every frame, the scene never still) is relit
    # LIGHT_INTERVAL_S after the first change, and again after each relight, though its own
    # colour write tags the mesh; the last relight equals pressing Precompute for the light where
    # it stopped. A deformation during the drag waits for the scene to be still (DEBOUNCE_S).
    import bpy

    from addon import follow, session

    mat, obj, light = lit_sphere(bpy)
    first = read_preview(obj)
    clock = [100.0]
    monkeypatch.setattr(follow, "_clock", lambda: clock[0])
    bpy.context.view_layer.update()  # the precompute's own write, as Blender shows it at once
    follow.follow_now()
    relits = []
    for frame in range(24):  # 0.4 s at 60 Hz, never still for DEBOUNCE_S
        light.location.x += 0.01
        bpy.context.view_layer.update()
        before = session.SESSIONS[mat.name]
        follow.follow_tick()
        if session.SESSIONS[mat.name] is not before:
            relits.append(frame)
            assert session.SESSIONS[mat.name].follow_message.startswith("relit:")
        clock[0] += 1.0 / 60.0
    # Due LIGHT_INTERVAL_S (3 frames) after the first change, and as long again after the first
    # change following each relight: every 4-5 frames (waiting for stillness: never).
    assert len(relits) >= 4 and relits[0] <= 4, relits
    assert not np.allclose(read_preview(obj), first)
    # The drag stops; the last change is relit as a precompute would show it.
    clock[0] += 1.0
    follow.follow_tick()
    assert not follow.PENDING or follow.follow_tick() is None
    relit_like_a_precompute(bpy, session, mat, obj)
    # A deformation while the light moves: not relit until the scene is still.
    sess = session.SESSIONS[mat.name]
    obj.modifiers["Displace"].strength = 0.01
    light.location.x += 0.01
    bpy.context.view_layer.update()
    clock[0] += 0.1
    follow.follow_tick()
    assert session.SESSIONS[mat.name] is sess and mat.name in follow.PENDING
    assert session.SESSIONS[mat.name].deformed == {obj.name: "deformed"}
    clock[0] += follow.DEBOUNCE_S
    follow.follow_tick()
    assert session.SESSIONS[mat.name] is not sess and session.state(mat) == "ready"


def test_a_floors_colour_edit_relights_what_it_sends_back(addon):
    # Issue 30: the floor under the sphere sends light back by its Base Color; painting it black
    # is followed (relit, no walk traced), and the sphere's underside, lit by the floor alone,
    # goes dark.
    import bpy

    from addon import follow, session

    mat, obj, _ = lit_sphere(bpy)
    alone = read_preview(obj).copy()
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(0.0, 0.0, -0.045))
    floor = bpy.context.active_object
    paint = bpy.data.materials.new("Floor paint")
    node = next(n for n in paint.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    node.inputs["Base Color"].default_value = (0.8, 0.8, 0.8, 1.0)
    floor.data.materials.append(paint)
    bpy.context.view_layer.update()
    follow.follow_now()
    lit_floor = read_preview(obj).copy()
    p = np.array([v.co for v in obj.data.vertices])
    under = p[:, 2] < -0.03
    # Summed over the underside: a vertex at the edge of the sphere's own shadow on the floor
    # gets a few rays' worth, which Monte Carlo may leave at 0 on another machine.
    assert lit_floor[under].sum() > 100.0 * alone[under].sum()
    seen = lit_floor[under].sum(axis=1) > 0.1 * lit_floor[under].sum(axis=1).max()
    node.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bpy.context.view_layer.update()
    follow.follow_now()
    assert session.SESSIONS[mat.name].follow_message.startswith("relit:")
    dark = relit_like_a_precompute(bpy, session, mat, obj)
    assert dark[under].sum() < 0.2 * lit_floor[under].sum()
    assert np.all(dark[under][seen].sum(axis=1) < 0.2 * lit_floor[under][seen].sum(axis=1))


def test_with_a_ui_the_lights_layers_are_made_after_a_refresh_so_the_first_power_drag_casts_no_ray(
        addon, monkeypatch):
    """With a UI, once a PRT transport is shown, each light's own layer is made on a worker
    thread (`jobs.LayersPrep`, `Prt.prepare_layers`): the first drag of one light's power
    among several then adds its layer ("the light's layer rescaled": no ray) instead of
    relighting the transport under that light first. The preview is what Precompute gives for
    the changed light (the dipole: nothing else depends on it; 1e-3). A new job stops the
    making; headless, none is made."""
    import bpy

    from addon import follow, jobs, panel, session

    mat, obj, light = lit_sphere(bpy)
    mat.translucent.profile = "DIPOLE"
    rim = key_light(bpy, location=(0.0, 0.15, 0.05), energy=8.0)
    rim.name = "Rim"
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    assert session.SESSIONS[mat.name].layers is None  # headless: none made
    timers = []
    monkeypatch.setattr(jobs, "headless", lambda: False)
    monkeypatch.setattr(bpy.app.timers, "register", lambda fn, first_interval=0.0, persistent=False: timers.append(fn))
    monkeypatch.setattr(bpy.app.timers, "is_registered", lambda fn: fn in timers)

    def refresh():
        bpy.context.view_layer.update()
        follow.follow_now()
        session.JOBS[mat.name]._thread.join(timeout=120)
        poll = next(fn for fn in timers if fn.__name__ == "poll")
        timers.remove(poll)
        assert poll() is None, "the job is done"
        return session.SESSIONS[mat.name]

    light.location.x += 0.05  # a move: the transport relit, then its layers made
    sess = refresh()
    assert sess.follow_message.startswith("relit:"), sess.follow_message
    assert isinstance(sess.layers, jobs.LayersPrep)
    sess.layers._thread.join(timeout=120)
    assert sess.layers.message.startswith("lights' layers ready: 2"), sess.layers.message
    assert sess.layers.message in [t for t, _ in panel.status_lines(mat)]
    rim.data.energy = 12.0  # the first change of Rim's power
    sess = refresh()
    assert "the light's layer rescaled" in sess.follow_message, sess.follow_message
    assert " 0 rays" in sess.follow_message, sess.follow_message
    dragged = read_preview(obj).copy()
    monkeypatch.setattr(jobs, "headless", lambda: True)
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    np.testing.assert_allclose(dragged, read_preview(obj), rtol=1e-3, atol=1e-6 * dragged.max())
    monkeypatch.setattr(jobs, "headless", lambda: False)

    class Slow:  # a transport whose layers take long: goes on until told to stop
        def prepare_layers(self, scene, progress):
            while progress(0.5):
                time.sleep(0.01)
            raise translucent.Cancelled("stopped")

    class Broken:
        def prepare_layers(self, scene, progress):
            raise ValueError("lights: not the lights this transport was lit with")

    broken = jobs.LayersPrep(Broken(), None)
    broken._thread.join(timeout=10)
    assert broken.message == ("the lights' layers were not prepared: lights: not the lights this transport was "
                              "lit with"), broken.message
    session.SESSIONS[mat.name].layers = slow = jobs.LayersPrep(Slow(), None)
    assert not slow.done
    light.location.x -= 0.05  # another job on the material: the making is stopped first
    refresh()
    assert slow.done and slow.message == "", slow.message


def _as_with_a_ui(monkeypatch, mat):
    """The add-on as with a window: jobs on worker threads, timers kept to be run by hand, the
    scene follower's clock set by the test. Returns the clock ([seconds]) and `run_job(kind)`,
    which waits for `mat`'s job (of that kind) and runs its poll."""
    import bpy

    from addon import follow, jobs, session

    timers = []
    clock = [100.0]
    monkeypatch.setattr(follow, "_clock", lambda: clock[0])
    monkeypatch.setattr(jobs, "headless", lambda: False)
    monkeypatch.setattr(bpy.app.timers, "register", lambda fn, first_interval=0.0, persistent=False: timers.append(fn))
    monkeypatch.setattr(bpy.app.timers, "is_registered", lambda fn: fn in timers)

    def run_job(kind):
        job = session.JOBS[mat.name]
        assert isinstance(job, kind), job
        job._thread.join(timeout=120)
        poll = next(fn for fn in timers if fn.__name__ == "poll")
        timers.remove(poll)
        assert poll() is None, "the job is done"

    return clock, run_job


def test_with_a_ui_a_dragged_light_is_followed_by_the_hierarchy_with_the_walks_then_prt_relights(
        addon, monkeypatch):
    """Issue 29 point 5: with a UI, once a PRT preview with the walks is shown, a hierarchy is
    built beside it from the precompute's walks (`drag.DragPrep`, `Hierarchy(walks_from=...)`);
    a light being dragged is then followed by that hierarchy ("relit (dragging)", the PRT
    transport untouched), and PRT relights once the light has been still for DEBOUNCE_S. The
    dragged preview is judged against that PRT relight for the same light (another method's
    transport, the same walks); the user's mesh is untouched."""
    import bpy

    from addon import drag, follow, jobs, panel, session

    mat, obj, light = lit_sphere(bpy)
    user_mesh = mesh_hash(obj.data)
    clock, run_job = _as_with_a_ui(monkeypatch, mat)

    # A move, then still: PRT relit, and the drag's hierarchy built beside it.
    light.location.x += 0.05
    bpy.context.view_layer.update()
    follow.follow_now()
    run_job(jobs.RelightJob)
    sess = session.SESSIONS[mat.name]
    assert sess.follow_message.startswith("relit:"), sess.follow_message
    assert isinstance(sess.drag, drag.DragPrep)
    sess.drag._thread.join(timeout=120)
    assert sess.drag.ready and sess.drag.message.startswith("light drag ready"), sess.drag.message
    assert sess.drag.message in [t for t, _ in panel.status_lines(mat)]
    prt, prep = sess.transport, sess.drag
    first_seen = read_preview(obj).copy()
    # The light dragged on: LIGHT_INTERVAL_S after the change, a step of the drag's hierarchy.
    light.location.x += 0.03
    bpy.context.view_layer.update()
    clock[0] += follow.LIGHT_INTERVAL_S + 0.001
    follow.follow_tick()
    run_job(drag.DragJob)
    assert session.SESSIONS[mat.name] is sess and sess.transport is prt, "PRT is not relit while dragging"
    assert sess.follow_message.startswith("relit (dragging)"), sess.follow_message
    assert sess.follow_message in [t for t, _ in panel.status_lines(mat)]
    assert follow.PENDING[mat.name].settle and not follow.PENDING[mat.name].dragging
    dragged = read_preview(obj).copy()
    assert sess.last_eval["method"] == "hierarchy" and sess.last_error is not None
    # Still for DEBOUNCE_S: PRT relights for the light where it stopped; the drag is kept.
    bpy.context.view_layer.update()  # the drag's own write
    clock[0] += follow.DEBOUNCE_S + 0.01
    follow.follow_tick()
    run_job(jobs.RelightJob)
    relit = session.SESSIONS[mat.name]
    assert relit is not sess and relit.follow_message.startswith("relit:"), relit.follow_message
    assert relit.drag is prep, "the drag's hierarchy is carried to the relit transport"
    after = read_preview(obj)
    rel = np.sqrt(np.mean((dragged - after) ** 2, axis=0) / np.mean(after**2, axis=0))
    moved = np.sqrt(np.mean((first_seen - after) ** 2, axis=0) / np.mean(after**2, axis=0))
    # 0.4-0.6 % here (1.2-1.3 % from a fresh precompute on the 10 cm bunny), where the move
    # itself changed the preview by 18 %.
    assert np.all(rel < 0.03) and np.all(moved > 5.0 * rel), (rel, moved)
    # After an edit the drag's hierarchy is not evaluated for another material in a drag step:
    # that step PRT builds its transport again (relit, or precomputed for a medium it was not
    # chosen for), and the drag's hierarchy is built again for the edited material.
    mat.translucent.sigma_a = (0.02, 0.03, 0.05)
    light.location.x += 0.02
    bpy.context.view_layer.update()
    clock[0] += follow.LIGHT_INTERVAL_S + 0.001
    follow.follow_tick()
    run_job(jobs.Job)
    assert session.SESSIONS[mat.name].last_eval["method"] == "prt"
    rebuilt = session.SESSIONS[mat.name].drag
    assert rebuilt is not prep and rebuilt.key[0] == session.params(mat.translucent)
    rebuilt._thread.join(timeout=120)
    assert rebuilt.ready, rebuilt.message
    assert mesh_hash(obj.data) == user_mesh
    # A deformation since: the transport follows the pose and the drag's hierarchy is built
    # again on it (the rest pose's would drag the rest pose's shape and walks).
    obj.modifiers["Displace"].strength = 0.01
    bpy.context.view_layer.update()
    clock[0] += follow.DEBOUNCE_S + 0.01
    follow.follow_tick()
    run_job(jobs.Job)
    posed = session.SESSIONS[mat.name]
    assert posed.drag is not rebuilt and np.array_equal(posed.drag.info.positions, posed.info.positions)
    posed.drag.stop()


def test_with_a_ui_a_light_dragged_over_a_floor_keeps_the_floors_bounce(addon, monkeypatch):
    """A light dragged over the sphere resting on a floor that sends light back (Blender's
    default grey): the drag's hierarchy takes the floor's bounce from its vertices' rays,
    averaged over their rings (`Hierarchy::bounce_at`), and the dragged preview is judged
    against PRT's relight for the same light, whose bounce is gathered at every sample: 3.6-3.7 %
    here, where one or two bounce rays at each face's point left it 6.7-6.9 % (7-8 % on Suzanne
    on a floor). The underside, lit by the floor alone, keeps its light."""
    import bpy

    from addon import drag, follow, jobs, session

    bpy.ops.mesh.primitive_plane_add(size=0.5, location=(0.0, 0.0, -0.041))
    floor = bpy.context.active_object
    floor_mesh = mesh_hash(floor.data)
    mat, obj, light = lit_sphere(bpy)
    clock, run_job = _as_with_a_ui(monkeypatch, mat)

    light.location.x += 0.05
    bpy.context.view_layer.update()
    follow.follow_now()
    run_job(jobs.RelightJob)
    sess = session.SESSIONS[mat.name]
    assert sess.info.occluder_keys, "the floor is exported as an occluder"
    sess.drag._thread.join(timeout=120)
    assert sess.drag.ready, sess.drag.message
    light.location.x += 0.03
    bpy.context.view_layer.update()
    clock[0] += follow.LIGHT_INTERVAL_S + 0.001
    follow.follow_tick()
    run_job(drag.DragJob)
    assert sess.follow_message.startswith("relit (dragging)"), sess.follow_message
    dragged = read_preview(obj).copy()
    stated = np.array(sess.last_error)
    bpy.context.view_layer.update()
    clock[0] += follow.DEBOUNCE_S + 0.01
    follow.follow_tick()
    run_job(jobs.RelightJob)
    after = read_preview(obj)
    rel = np.sqrt(np.mean((dragged - after) ** 2, axis=0) / np.mean(after**2, axis=0))
    assert np.all(np.isfinite(dragged)) and np.all(rel < 0.05), (rel, stated)
    # The floor's light reaches the underside in the dragged preview as in PRT's.
    below = obj.data.vertices
    z = np.array([v.co.z for v in below])
    under = z < -0.03
    assert under.any() and np.all(dragged[under].mean(0) > 0.7 * after[under].mean(0)), (
        dragged[under].mean(0), after[under].mean(0))
    assert mesh_hash(floor.data) == floor_mesh
