"""Light and shadow linking, and emissive meshes (issue 30 point 1), in headless Blender. A light
whose receiver collection leaves out the previewed object lights nothing of it in Cycles, so the
preview must be the one of the scene without that light (Blender's rule: only included objects ->
those alone; only excluded -> all but those; none -> every object). What the export cannot follow
(a light lighting some previewed objects and not others, a floor it does not light, shadow
linking, an emissive mesh's light) is named in the panel, never silently dropped."""

import numpy as np
import pytest

from helpers import key_light, read_preview

pytestmark = pytest.mark.bpy


def _scene(bpy):
    """A 4 cm marble sphere (PRT, 8 coefficients) under the point light Key, a second point light
    Rim behind it, and a floor below it (an occluder)."""
    mat = bpy.data.materials.new("Wax")
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.04, segments=16, ring_count=8)
    obj = bpy.context.active_object
    obj.name = "Ball"
    obj.data.materials.append(mat)
    bpy.ops.mesh.primitive_plane_add(size=0.5, location=(0.0, 0.0, -0.05))
    bpy.context.active_object.name = "Floor"
    key_light(bpy)
    rim = key_light(bpy, location=(0.0, 0.15, 0.05), energy=8.0)
    rim.name = "Rim"
    s = mat.translucent
    s.enabled = True
    s.preset = "MARBLE"
    s.coefficients = 8
    s.method = "PRT"
    return mat, obj, rim


def _linking(bpy, name, entries):
    """A linking collection holding `entries`: (object, "INCLUDE" or "EXCLUDE") pairs."""
    coll = bpy.data.collections.new(name)
    for o, _ in entries:
        coll.objects.link(o)
    for entry, (_, state) in zip(coll.collection_objects, entries):  # in the objects' order
        entry.light_linking.link_state = state
    return coll


def _preview(bpy, mat, obj):
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    return read_preview(obj).copy()


def test_a_light_linked_away_from_the_previewed_object_is_the_scene_without_it(addon):
    import bpy

    from addon import export, panel, session

    mat, obj, rim = _scene(bpy)
    floor = bpy.data.objects["Floor"]
    with_rim = _preview(bpy, mat, obj)
    keys = export.lighting_keys(bpy.context.scene)
    rim.hide_render = True
    without_rim = _preview(bpy, mat, obj)
    assert np.abs(with_rim - without_rim).max() > 1e-3  # Rim lights the ball when not linked
    rim.hide_render = False
    # Only the floor included, then the ball excluded: either way Rim lights no vertex of the ball.
    for entries in ([(floor, "INCLUDE")], [(obj, "EXCLUDE")]):
        rim.light_linking.receiver_collection = _linking(bpy, "Rim receivers", entries)
        assert export.lighting_keys(bpy.context.scene) != keys  # following notices the change
        linked = _preview(bpy, mat, obj)
        np.testing.assert_allclose(linked, without_rim, rtol=1e-6, atol=1e-9)
        sess = session.SESSIONS[mat.name]
        assert sess.info.unlinked_lights == ["Rim"] and sess.info.lights == ["Key"]
        assert "left out (light linking): Rim" in panel.summary(sess)
    # The ball included: Rim lights it as with no linking at all.
    rim.light_linking.receiver_collection = _linking(bpy, "Rim on the ball", [(obj, "INCLUDE")])
    np.testing.assert_allclose(_preview(bpy, mat, obj), with_rim, rtol=1e-6, atol=1e-9)
    sess = session.SESSIONS[mat.name]
    # ... but not the floor, whose bounce of it is still counted: said so.
    assert any("does not light Floor" in line for line in sess.info.linking), sess.info.linking
    assert sorted(bpy.data.collections.keys()) == ["Rim on the ball", "Rim receivers", "Rim receivers.001"]


def test_shadow_linking_is_named_where_it_is_not_followed(addon):
    import bpy

    from addon import panel, session

    mat, obj, rim = _scene(bpy)
    floor = bpy.data.objects["Floor"]
    rim.light_linking.blocker_collection = _linking(bpy, "Rim blockers", [(floor, "EXCLUDE")])
    _preview(bpy, mat, obj)
    sess = session.SESSIONS[mat.name]
    lines = [text for text, _ in panel.status_lines(mat)]
    assert any("Rim's shadows are not cast by Floor in Cycles (shadow linking)" in t for t in lines), lines
    # Only the ball may block Rim: the floor's shadow not followed, the ball's own is.
    rim.light_linking.blocker_collection = _linking(bpy, "Rim blockers 2", [(obj, "INCLUDE")])
    _preview(bpy, mat, obj)
    sess = session.SESSIONS[mat.name]
    assert [line for line in sess.info.linking if "shadow linking" in line] == [
        "Rim's shadows are not cast by Floor in Cycles (shadow linking): they are here, not followed"]


def test_an_emissive_prop_is_named_as_light_not_followed(addon):
    # A plane with an Emission shader lights the scene in Cycles; the export makes it a shadow
    # (and a bounce), not a light, and the panel says so. A Principled BSDF with an Emission
    # Strength above 0 counts; one at 0 (Blender's default), or a black emission, does not.
    import bpy

    from addon import panel, session

    mat, obj, rim = _scene(bpy)
    panel_mat = bpy.data.materials.new("Panel")
    tree = panel_mat.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    emit = tree.nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = 5.0
    tree.links.new(emit.outputs["Emission"], tree.nodes["Material Output"].inputs["Surface"])
    bpy.ops.mesh.primitive_plane_add(size=0.1, location=(0.0, -0.2, 0.1))
    lamp = bpy.context.active_object
    lamp.name = "Softbox"
    lamp.data.materials.append(panel_mat)
    glow = bpy.data.materials.new("Glow")
    bsdf = glow.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Emission Color"].default_value = (1.0, 0.5, 0.2, 1.0)
    floor = bpy.data.objects["Floor"]
    floor.data.materials.append(glow)
    _preview(bpy, mat, obj)
    sess = session.SESSIONS[mat.name]
    assert sess.info.emitters == ["Softbox"]  # the floor's Emission Strength is 0
    lines = [text for text, _ in panel.status_lines(mat)]
    assert any(t.startswith("Softbox: emissive, lighting the scene in Cycles; not a light here") for t in lines), lines
    bsdf.inputs["Emission Strength"].default_value = 2.0
    _preview(bpy, mat, obj)
    assert sorted(session.SESSIONS[mat.name].info.emitters) == ["Floor", "Softbox"]
    bsdf.inputs["Emission Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    _preview(bpy, mat, obj)
    assert session.SESSIONS[mat.name].info.emitters == ["Softbox"]
