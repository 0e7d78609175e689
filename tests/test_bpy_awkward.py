"""Real scenes' awkward parts (issue 30 point 5), in headless Blender: a mesh linked from a
library is read-only (previewed nowhere, the panel says why and how, nothing of the library
written), while the other objects of the material are previewed; a material used by 50 objects
is previewed on all of them, each from its own vertex range, at the irradiance a sun gives."""

import numpy as np
import pytest

from helpers import draw_panel, key_light, mesh_hash, read_preview

pytestmark = pytest.mark.bpy


def wax_material(bpy):
    mat = bpy.data.materials.new("Wax")
    s = mat.translucent
    s.enabled, s.preset, s.profile, s.coefficients = True, "MARBLE", "DIPOLE", 8
    return mat


def sun(bpy):
    light = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    light.data.energy = 2.0
    bpy.context.scene.collection.objects.link(light)


def test_a_linked_mesh_is_never_written_and_the_panel_says_how_to_see_it(addon, tmp_path):
    import bpy

    from addon import session

    # A library file holding a ball whose mesh has one material slot.
    bpy.ops.mesh.primitive_ico_sphere_add(radius=0.03, subdivisions=2, location=(0.1, 0.0, 0.0))
    ball = bpy.context.active_object
    ball.name = ball.data.name = "Ball"
    ball.data.materials.append(bpy.data.materials.new("LibGrey"))
    library = tmp_path / "props.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(library), copy=True)
    bpy.data.objects.remove(ball)
    bpy.data.meshes.remove(bpy.data.meshes["Ball"])
    bpy.data.materials.remove(bpy.data.materials["LibGrey"])
    with bpy.data.libraries.load(str(library), link=True) as (_, into):
        into.meshes = ["Ball"]
    linked = bpy.data.objects.new("Linked ball", into.meshes[0])
    bpy.context.scene.collection.objects.link(linked)
    assert linked.data.library is not None and not linked.data.is_editable
    mat = wax_material(bpy)
    linked.material_slots[0].link = "OBJECT"  # a local material on a linked mesh
    linked.material_slots[0].material = mat
    bpy.ops.mesh.primitive_ico_sphere_add(radius=0.03, subdivisions=2, location=(-0.1, 0.0, 0.0))
    local = bpy.context.active_object
    local.data.materials.append(mat)
    sun(bpy)
    before = mesh_hash(linked.data), list(linked.data.color_attributes.keys())
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    sess = session.SESSIONS[mat.name]
    assert sorted(sess.objects) == sorted([linked.name, local.name])
    assert (mesh_hash(linked.data), list(linked.data.color_attributes.keys())) == before
    assert read_preview(local).max() > 0
    assert len(sess.not_shown) == 1 and sess.not_shown[0].startswith(f"{linked.name}: its mesh is linked from")
    assert "make it local or a library override" in " ".join(draw_panel(addon, mat))


def test_a_material_used_by_fifty_objects_is_previewed_on_each(addon):
    # Fifty 2 cm balls in a row under a sun straight down: each one's top gathers what a
    # sun-lit ball of its own would; the same everywhere, since none is in another's light.
    import bpy

    from addon import session

    mat = wax_material(bpy)
    bpy.ops.mesh.primitive_ico_sphere_add(radius=0.01, subdivisions=2)
    first = bpy.context.active_object
    first.data.materials.append(mat)
    balls = [first]
    for k in range(1, 50):
        ball = first.copy()  # sharing the mesh, as Alt+D does
        ball.location = (0.05 * k, 0.0, 0.0)
        bpy.context.scene.collection.objects.link(ball)
        balls.append(ball)
    sun(bpy)
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    sess = session.SESSIONS[mat.name]
    assert len(sess.objects) == 50 and sess.transport.vertex_count == 50 * len(first.data.vertices)
    # One shared mesh holds one attribute: what the last-written ball shows, the same as every
    # other ball's range of the transport (identical balls under the same sun).
    b = sess.transport.radiance(mat.translucent.material())
    ranges = np.stack([b[r.start:r.start + r.count] for r in sess.info.objects])
    np.testing.assert_allclose(ranges, np.broadcast_to(ranges.mean(axis=0), ranges.shape), rtol=0.05, atol=1e-4)
    np.testing.assert_allclose(read_preview(first), ranges[-1], rtol=1e-6)
    assert sess.not_shown == [f"50 objects share the mesh {first.data.name}: it shows {balls[-1].name}'s preview "
                              "(Object > Relations > Make Single User to see each)"]


def test_a_textured_base_color_is_followed_and_other_links_are_named(addon):
    # Issue 30 point 2: PRT reads a linked Base Color per vertex (the panel says from which
    # node); a link into another input the preview reads is named as not followed instead of
    # showing the socket's stale value silently.
    import bpy

    mat = bpy.data.materials.new("Skin")
    node = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    node.inputs["Subsurface Weight"].default_value = 1.0
    node.inputs["Subsurface Scale"].default_value = 0.01
    mat.translucent.enabled = True
    mat.translucent.source = "PRINCIPLED"
    assert not any("not followed" in t for t in draw_panel(addon, mat))
    tex = mat.node_tree.nodes.new("ShaderNodeTexNoise")
    mat.node_tree.links.new(tex.outputs["Color"], node.inputs["Base Color"])
    labels = " ".join(draw_panel(addon, mat))
    assert "Connected, not followed: Base Color (Noise Texture)" in labels  # nothing precomputed yet
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.04, segments=16, ring_count=8)
    bpy.context.active_object.data.materials.append(mat)
    key_light(bpy)
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    labels = " ".join(draw_panel(addon, mat))
    assert "Base Color from Noise Texture: read by Cycles at 114 vertices" in labels
    assert "not followed" not in labels
    value = mat.node_tree.nodes.new("ShaderNodeValue")
    value.outputs[0].default_value = 0.01
    mat.node_tree.links.new(value.outputs[0], node.inputs["Subsurface Scale"])
    labels = " ".join(draw_panel(addon, mat))
    assert "Connected, not followed: Subsurface Scale (Value)" in labels
