"""The add-on's operators from a script, in headless Blender (issue 28, point 5): the README's
`bpy.ops.translucent.precompute(material_name="Wax")` works whatever is active (an object
without the material, or nothing), writes the preview on the objects carrying the material
and changes nothing else; a missing or switched-off material is an error naming it."""

import numpy as np
import pytest

from helpers import key_light, mesh_hash, read_preview

pytestmark = pytest.mark.bpy


def scene_with_a_floor(bpy):
    """A small sphere with "Wax", a floor plane without it (active), a cube with another
    material, and a point light: more than one object, and the active one is not Wax's."""
    wax = bpy.data.materials.new("Wax")
    jade = bpy.data.materials.new("Jade")
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.04, segments=16, ring_count=8)
    sphere = bpy.context.active_object
    sphere.data.materials.append(wax)
    bpy.ops.mesh.primitive_cube_add(size=0.03, location=(0.12, 0.0, 0.0))
    cube = bpy.context.active_object
    cube.data.materials.append(jade)
    jade.translucent.enabled = True  # previewable, but not asked for
    bpy.ops.mesh.primitive_plane_add(size=0.5, location=(0.0, 0.0, -0.05))
    floor = bpy.context.active_object
    key_light(bpy)
    s = wax.translucent
    s.enabled = True
    s.preset = "MARBLE"
    s.profile = "DIPOLE"
    s.coefficients = 8
    bpy.context.view_layer.objects.active = floor
    return wax, sphere, cube, floor


def snapshot(bpy):
    """What a user owns that an operator could change: each object's mesh (the preview
    attribute left out), its colour attributes and materials, the active object, the selection,
    and each material's node tree."""
    objects = {o.name: (mesh_hash(o.data) if o.type == "MESH" else None,
                        sorted(a.name for a in o.data.color_attributes) if o.type == "MESH" else None,
                        [s.material.name if s.material else None for s in o.material_slots],
                        o.select_get(), tuple(o.location))
               for o in bpy.data.objects}
    active = bpy.context.view_layer.objects.active
    nodes = {m.name: sorted(m.node_tree.nodes.keys()) if m.node_tree else [] for m in bpy.data.materials}
    return objects, active.name if active else None, nodes


def test_precompute_by_name_works_with_another_object_active(addon):
    import bpy

    from addon import session, writeback

    wax, sphere, cube, floor = scene_with_a_floor(bpy)
    assert bpy.context.view_layer.objects.active == floor and floor.active_material is None
    before = snapshot(bpy)
    assert bpy.ops.translucent.precompute(material_name="Wax") == {"FINISHED"}
    preview = read_preview(sphere)
    assert np.all(np.isfinite(preview)) and preview.max() > 0 and preview.min() >= 0
    assert floor.data.color_attributes.get(writeback.ATTRIBUTE) is None
    assert cube.data.color_attributes.get(writeback.ATTRIBUTE) is None
    assert list(session.SESSIONS) == ["Wax"] and session.SESSIONS["Wax"].objects == [sphere.name]
    objects, active, nodes = snapshot(bpy)
    # Only the sphere's colour attributes gained the preview; everything else is as it was.
    assert objects[sphere.name][1] == sorted(before[0][sphere.name][1] + [writeback.ATTRIBUTE])
    objects[sphere.name] = objects[sphere.name][:1] + before[0][sphere.name][1:2] + objects[sphere.name][2:]
    assert (objects, active, nodes) == before

    # With no active object at all, the same preview.
    bpy.ops.translucent.clear(material_name="Wax")
    assert sphere.data.color_attributes.get(writeback.ATTRIBUTE) is None and "Wax" not in session.SESSIONS
    bpy.context.view_layer.objects.active = None
    assert bpy.ops.translucent.precompute(material_name="Wax") == {"FINISHED"}
    assert bpy.context.view_layer.objects.active is None
    np.testing.assert_array_equal(read_preview(sphere), preview)

    # And the same as from the material's own context (the sphere active, no name given).
    bpy.ops.translucent.clear(material_name="Wax")
    bpy.context.view_layer.objects.active = sphere
    assert bpy.ops.translucent.precompute() == {"FINISHED"}
    np.testing.assert_array_equal(read_preview(sphere), preview)
    assert floor.data.color_attributes.get(writeback.ATTRIBUTE) is None
    assert cube.data.color_attributes.get(writeback.ATTRIBUTE) is None


def test_a_missing_or_switched_off_material_is_an_error_naming_it(addon):
    import bpy

    from addon import session

    wax, sphere, cube, floor = scene_with_a_floor(bpy)
    before = snapshot(bpy)
    with pytest.raises(RuntimeError, match="material_name: no material named 'Nope'"):
        bpy.ops.translucent.precompute(material_name="Nope")
    with pytest.raises(RuntimeError, match="material_name: no material named 'Nope'"):
        bpy.ops.translucent.clear(material_name="Nope")
    wax.translucent.enabled = False
    with pytest.raises(RuntimeError, match="material 'Wax': the preview is off"):
        bpy.ops.translucent.precompute(material_name="Wax")
    # No name and nothing to take it from (the floor has no material): said so, not a poll failure.
    with pytest.raises(RuntimeError, match="no material: pass material_name"):
        bpy.ops.translucent.precompute()
    bpy.context.view_layer.objects.active = None
    with pytest.raises(RuntimeError, match="no material: pass material_name"):
        bpy.ops.translucent.clear()
    bpy.context.view_layer.objects.active = floor
    assert not session.SESSIONS and not session.JOBS
    assert snapshot(bpy) == before
