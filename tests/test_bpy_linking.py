"""Light and shadow linking (issue 30 point 1), in headless Blender: a light whose receiver
collection leaves out the previewed object lights nothing of it in Cycles, so the preview must be
the one of the scene without that light (Blender's rule: only included objects -> those alone;
only excluded -> all but those; none -> every object); what the export cannot follow (a light
lighting some previewed objects and not others, a floor it does not light, shadow linking) is
named in the panel, never silently dropped."""

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
