"""The add-on as an artist or a script drives it, in headless Blender: register twice, enable
the preview, precompute, edit a slider, two objects sharing a material, stale detection,
cancelling, save and reload; the user's data stays untouched."""

import numpy as np
import pytest

from helpers import key_light, mesh_hash, read_preview

pytestmark = pytest.mark.bpy


def scene_with_two_spheres(bpy):
    mat = bpy.data.materials.new("Wax")
    objs = []
    for x in (-0.06, 0.06):
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.04, location=(x, 0.0, 0.0), segments=24, ring_count=12)
        o = bpy.context.active_object
        o.data.materials.append(mat)
        objs.append(o)
    smooth = objs[0].modifiers.new("Smooth", "SMOOTH")  # keeps the vertex count
    smooth.factor = 0.5
    light = key_light(bpy, (0.0, -0.2, 0.2))
    bpy.context.view_layer.objects.active = objs[0]
    return mat, objs, light


def test_register_and_unregister_twice(empty_blend):
    import addon

    for _ in range(2):
        addon.register()
        assert hasattr(empty_blend.types.Material, "translucent")
        addon.unregister()
        assert not hasattr(empty_blend.types.Material, "translucent")


def test_precompute_and_live_edit_touch_only_the_preview_attribute(addon):
    import bpy

    from addon import session

    mat, objs, light = scene_with_two_spheres(bpy)
    before = [mesh_hash(o.data) for o in objs]
    nodes_before = mat.node_tree.nodes.keys() if mat.node_tree else []
    s = mat.translucent
    s.enabled = True
    s.mm_per_unit = 1000.0
    s.preset = "MARBLE"
    assert tuple(round(x, 4) for x in s.sigma_s) == (2.19, 2.62, 3.0)
    assert session.state(mat) == "none"
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    assert session.state(mat) == "ready"
    first = [read_preview(o) for o in objs]
    for f in first:
        assert np.all(np.isfinite(f)) and f.max() > 0 and f.min() >= 0
    # Dragging a slider refits and rewrites the attribute of both objects sharing the material.
    s.sigma_a = (0.5, 0.5, 0.5)
    second = [read_preview(o) for o in objs]
    for f, g in zip(first, second):
        assert np.all(g <= f + 1e-6) and g.sum() < 0.9 * f.sum(), "more absorption, darker"
    sess = session.SESSIONS[mat.name]
    assert sess.last_seconds > 0 and len(sess.last_error) == 3
    assert [mesh_hash(o.data) for o in objs] == before
    assert (mat.node_tree.nodes.keys() if mat.node_tree else []) == nodes_before
    assert len(objs[0].modifiers) == 1
    # Moving the light makes the transport stale; so does a new IOR.
    light.location.x += 0.05
    bpy.context.view_layer.update()
    assert session.state(mat) == "stale"


def test_cancel_leaves_no_transport(addon):
    import bpy

    import translucent
    from addon import jobs, session

    mat, objs, _ = scene_with_two_spheres(bpy)
    mat.translucent.enabled = True
    job, *_ = jobs.start(mat)
    job.cancel = True
    job.run_here()
    assert isinstance(job.error, translucent.Cancelled)
    assert mat.name not in session.SESSIONS


def test_settings_survive_save_and_reload_but_transport_does_not(addon, tmp_path):
    import bpy

    from addon import session

    mat, objs, _ = scene_with_two_spheres(bpy)
    mat.translucent.enabled = True
    mat.translucent.sigma_a = (0.01, 0.02, 0.03)
    bpy.ops.translucent.precompute(material_name=mat.name)
    path = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    mat = bpy.data.materials["Wax"]
    assert mat.translucent.enabled
    assert tuple(round(x, 4) for x in mat.translucent.sigma_a) == (0.01, 0.02, 0.03)
    assert session.state(mat) == "none", "transport is not saved: the panel asks for a precompute"


def test_an_edit_outside_the_basis_range_is_flagged_and_refreshed(addon):
    import bpy

    from addon import session

    mat, objs, _ = scene_with_two_spheres(bpy)
    s = mat.translucent
    s.enabled = True
    s.mm_per_unit = 1000.0
    s.preset = "MARBLE"
    s.auto_refresh = False
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    sess = session.SESSIONS[mat.name]
    assert not sess.refresh_advised
    marble = (tuple(s.sigma_a), tuple(s.sigma_s))
    # Five times thinner: a profile five times wider than the knots and the support radius were
    # chosen for (denser materials are safe: the receiver's disc is exact in the stiff limit).
    s.sigma_s = tuple(0.2 * x for x in marble[1])
    s.sigma_a = tuple(0.2 * x for x in marble[0])
    flagged = max(sess.last_error)
    assert sess.refresh_advised and flagged > 0.01
    assert session.SESSIONS[mat.name] is sess, "no refresh while auto refresh is off"
    # With auto refresh on, the next edit precomputes again for the material it shows.
    s.auto_refresh = True
    s.g = 0.0
    fresh = session.SESSIONS[mat.name]
    assert fresh is not sess and not fresh.refresh_advised
    assert max(fresh.last_error) < flagged
    assert fresh.chosen_for == session.params(s)
    assert mat.name not in session.JOBS


def test_viewports_show_the_preview_and_get_back_what_they_had(addon):
    import bpy

    from addon import session, writeback

    mat, objs, _ = scene_with_two_spheres(bpy)
    user = objs[1].data.color_attributes.new("Paint", "BYTE_COLOR", "CORNER")
    objs[1].data.color_attributes.active_color_name = user.name
    solid = [a.spaces.active.shading for s in bpy.data.screens for a in s.areas
             if a.type == "VIEW_3D" and a.spaces.active.shading.type == "SOLID"]
    assert solid, "the factory start-up file has Solid 3D viewports"
    before = [sh.color_type for sh in solid]
    mat.translucent.enabled = True
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    assert all(o.data.color_attributes.active_color_name == writeback.ATTRIBUTE for o in objs)
    assert all(sh.color_type == "VERTEX" for sh in solid)
    mat.translucent.enabled = False
    assert objs[1].data.color_attributes.active_color_name == "Paint"
    assert [sh.color_type for sh in solid] == before
    # On again: shown again from the transport still in memory.
    mat.translucent.enabled = True
    assert objs[0].data.color_attributes.active_color_name == writeback.ATTRIBUTE
    assert all(sh.color_type == "VERTEX" for sh in solid)
    # Clearing the preview removes the attribute and puts everything back as well.
    bpy.context.view_layer.objects.active = objs[1]
    assert bpy.ops.translucent.clear() == {"FINISHED"}
    assert mat.name not in session.SESSIONS
    assert objs[1].data.color_attributes.active_color_name == "Paint"
    assert all(o.data.color_attributes.get(writeback.ATTRIBUTE) is None for o in objs)
    assert [sh.color_type for sh in solid] == before


def test_undo_and_redo_bring_back_settings_and_preview_together(addon):
    import bpy

    mat, objs, _ = scene_with_two_spheres(bpy)
    names = [o.name for o in objs]
    s = mat.translucent
    s.enabled = True
    s.auto_refresh = False
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    assert bpy.ops.ed.undo_push(message="precompute") == {"FINISHED"}
    first = [read_preview(o) for o in objs]
    sigma_a = tuple(s.sigma_a)
    # A slider drag in the UI pushes its own undo step; a script pushes it by hand.
    s.sigma_a = (0.05, 0.05, 0.05)
    assert bpy.ops.ed.undo_push(message="absorption") == {"FINISHED"}
    second = [read_preview(bpy.data.objects[n]) for n in names]
    assert not np.allclose(first[0], second[0])
    assert bpy.ops.ed.undo() == {"FINISHED"}
    assert tuple(bpy.data.materials["Wax"].translucent.sigma_a) == pytest.approx(sigma_a)
    for n, f in zip(names, first):
        np.testing.assert_array_equal(read_preview(bpy.data.objects[n]), f)
    assert bpy.ops.ed.redo() == {"FINISHED"}
    assert tuple(bpy.data.materials["Wax"].translucent.sigma_a) == pytest.approx((0.05, 0.05, 0.05))
    for n, g in zip(names, second):
        np.testing.assert_array_equal(read_preview(bpy.data.objects[n]), g)


def test_only_objects_carrying_the_material_are_exported_and_the_rest_is_reported(addon):
    import bpy

    from addon import panel, session

    mat, objs, _ = scene_with_two_spheres(bpy)
    bpy.ops.mesh.primitive_cube_add(size=0.05, location=(0.0, 0.0, -0.2))
    other = bpy.context.active_object
    dark = bpy.data.objects.new("Dark", bpy.data.lights.new("Dark", "POINT"))
    dark.data.energy = 0.0
    bpy.context.scene.collection.objects.link(dark)
    bpy.context.view_layer.objects.active = objs[0]
    mat.translucent.enabled = True
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    sess = session.SESSIONS[mat.name]
    assert sess.info.skipped_objects == [other.name]
    assert sess.transport.report["vertices"] == sum(len(o.data.vertices) for o in objs)
    text = panel.summary(sess)
    assert "2 object(s) (1 without the material skipped)" in text
    assert "1 light(s) used, 1 dark" in text and "no rays (black)" in text


def test_a_subdivided_object_shows_the_preview_through_its_original_vertices(addon):
    import bpy

    from addon import session

    mat, objs, _ = scene_with_two_spheres(bpy)
    sub = objs[1].modifiers.new("Subdivision", "SUBSURF")
    sub.levels = 1
    before = mesh_hash(objs[1].data)
    mat.translucent.enabled = True
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    sess = session.SESSIONS[mat.name]
    assert sess.not_shown == []
    r = next(r for r in sess.info.objects if r.name == objs[1].name)
    assert r.count > len(objs[1].data.vertices), "the modifier adds vertices"
    # Each original vertex holds the value of the evaluated vertex nearest to it: compare with
    # a brute-force nearest search over the exported positions.
    depsgraph = bpy.context.evaluated_depsgraph_get()
    from addon import export

    evaluated, _, _ = export.evaluated_mesh_arrays(objs[1], depsgraph)
    co = np.array([tuple(objs[1].matrix_world @ v.co) for v in objs[1].data.vertices])
    nearest = np.argmin(((co[:, None, :] - evaluated[None, :, :]) ** 2).sum(-1), axis=1)
    values = sess.transport.radiance(mat.translucent.material())[r.start : r.start + r.count]
    np.testing.assert_allclose(read_preview(objs[1]), values[nearest], rtol=1e-6)
    assert mesh_hash(objs[1].data) == before


def test_enabling_the_preview_starts_from_the_principled_subsurface_inputs(addon):
    import bpy

    from translucent import cycles

    mat = bpy.data.materials.new("Jade")
    if mat.node_tree is None:  # Blender < 5.0 (5.0 always has nodes; use_nodes is deprecated)
        mat.use_nodes = True
    node = mat.node_tree.nodes["Principled BSDF"]
    target = cycles.to_principled((2.0, 5.0, 9.0), (300.0, 400.0, 500.0), 0.2, 1.4)  # per metre
    cycles.apply_to_principled(node, target)
    before = [tuple(i.default_value) if hasattr(i.default_value, "__len__") else i.default_value
              for i in node.inputs if hasattr(i, "default_value")]
    s = mat.translucent
    s.mm_per_unit = 1000.0
    s.enabled = True
    np.testing.assert_allclose(np.array(s.sigma_a) * 1000.0, (2.0, 5.0, 9.0), rtol=1e-4)
    np.testing.assert_allclose(np.array(s.sigma_s) * 1000.0, (300.0, 400.0, 500.0), rtol=1e-4)
    assert s.g == pytest.approx(0.2) and s.eta == pytest.approx(1.4)
    after = [tuple(i.default_value) if hasattr(i.default_value, "__len__") else i.default_value
             for i in node.inputs if hasattr(i, "default_value")]
    assert after == before, "the user's material is read, never written"
    # Only the first time: later toggles keep the artist's edits.
    s.sigma_a = (0.1, 0.1, 0.1)
    s.enabled = False
    s.enabled = True
    assert tuple(s.sigma_a) == pytest.approx((0.1, 0.1, 0.1))


def test_the_preview_follows_the_principled_bsdf_with_cycles_profile(addon):
    """Following the node (the default when it has subsurface): every input Cycles' answer
    depends on is read as it changes, the preview is Cycles' profile for exactly those inputs,
    and the node itself is never written."""
    import bpy

    import translucent
    from addon import session

    mat, objs, _ = scene_with_two_spheres(bpy)
    node = mat.node_tree.nodes["Principled BSDF"]  # Blender 5.0 materials always have nodes
    node.inputs["Subsurface Weight"].default_value = 1.0
    node.inputs["Subsurface Scale"].default_value = 0.01
    node.inputs["Base Color"].default_value = (0.8, 0.5, 0.3, 1.0)
    s = mat.translucent
    s.enabled = True
    assert s.source == "PRINCIPLED" and s.profile == "CYCLES"
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    sess = session.SESSIONS[mat.name]
    assert sess.transport.profile == "cycles"

    def expected():
        p = (tuple(node.inputs["Base Color"].default_value)[:3], tuple(node.inputs["Subsurface Radius"].default_value),
             node.inputs["Subsurface Scale"].default_value)
        m = translucent.Material.from_principled(
            *p, anisotropy=node.inputs["Subsurface Anisotropy"].default_value, ior=node.inputs["IOR"].default_value,
            roughness=node.inputs["Roughness"].default_value,
            subsurface_weight=node.inputs["Subsurface Weight"].default_value,
            metallic=node.inputs["Metallic"].default_value,
            transmission=node.inputs["Transmission Weight"].default_value)
        return sess.transport.radiance(m)[: len(objs[0].data.vertices)]

    np.testing.assert_allclose(read_preview(objs[0]), expected(), rtol=1e-5, atol=1e-7)
    before = read_preview(objs[0])
    for socket, value in [("Roughness", 0.2), ("Subsurface Weight", 0.6), ("IOR", 1.6), ("Metallic", 0.25),
                          ("Subsurface Anisotropy", 0.3)]:
        node.inputs[socket].default_value = value
        bpy.context.view_layer.update()  # the depsgraph handler sees the edit
        assert session.state(mat) == "ready", socket  # no new precompute for any of them
        now = read_preview(objs[0])
        assert not np.allclose(now, before), f"{socket} did not change the preview"
        np.testing.assert_allclose(now, expected(), rtol=1e-5, atol=1e-7)
        before = now
    # The coefficient fields show the medium followed (per mm), g as Cycles clamps it.
    assert s.g == pytest.approx(0.3)
    # Switching to the dipole asks for a precompute; an explicit coefficient edit means Custom.
    s.profile = "DIPOLE"
    assert session.state(mat) == "stale"
    s.profile = "CYCLES"
    s.sigma_a = (0.01, 0.01, 0.01)
    assert s.source == "CUSTOM"
