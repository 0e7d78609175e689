"""The add-on's exporter and write-back, in a real (headless) Blender."""

import math

import numpy as np
import pytest

from helpers import mesh_hash

pytestmark = pytest.mark.bpy


def test_export_applies_modifiers_in_world_space(empty_blend):
    bpy = empty_blend
    from addon import export

    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(1.0, 2.0, 3.0))
    cube = bpy.context.active_object
    mod = cube.modifiers.new("Subdivision", "SUBSURF")
    mod.levels = 2
    before = mesh_hash(cube.data)
    scene, info = export.export_scene([cube])
    # A cube at subdivision level 2 (Catmull–Clark): 98 vertices, 96 quads = 192 triangles.
    assert scene.vertex_count == 98
    assert scene.triangle_count == 192
    assert info.objects[0].count == 98
    # Evaluated and moved: Catmull–Clark shrinks the cube inside [-1, 1]^3 around (1, 2, 3).
    assert len(cube.data.vertices) == 8, "the user's mesh keeps its 8 vertices"
    assert mesh_hash(cube.data) == before, "export must not change the user's mesh"
    assert len(cube.modifiers) == 1


def test_export_lights_and_world_in_blender_units(empty_blend):
    bpy = empty_blend
    from addon import export

    bpy.ops.mesh.primitive_plane_add(size=2.0)
    plane = bpy.context.active_object
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = 3.0
    sun.rotation_euler = (math.radians(60.0), 0.0, 0.0)  # tilts -Z toward +Y
    bpy.context.scene.collection.objects.link(sun)
    dark = bpy.data.objects.new("Dark", bpy.data.lights.new("Dark", "POINT"))
    dark.data.energy = 0.0
    bpy.context.scene.collection.objects.link(dark)
    world = bpy.data.worlds.new("W")
    bpy.context.scene.world = world
    world.color = (0.0, 0.0, 0.0)
    if world.node_tree is not None:  # Blender 5 worlds always have nodes
        bg = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
        bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    scene, info = export.export_scene([plane])
    assert info.lights == ["Sun"] and info.skipped_lights == ["Dark"]
    assert info.world == "black"
    # The irradiance a sun of Strength 3 at 60 degrees gives a horizontal plane: 3 cos 60.
    e = scene.irradiance(eta=1.0)
    np.testing.assert_allclose(e, 1.5, rtol=1e-5)
    bg.inputs["Color"].default_value = (0.2, 0.1, 0.05, 1.0)
    bg.inputs["Strength"].default_value = 2.0
    scene, info = export.export_scene([plane])
    assert info.world == "uniform"
    # An unoccluded plane under a uniform world of radiance L receives pi L (plus the sun).
    e = scene.irradiance(eta=1.0, world_samples=256)
    np.testing.assert_allclose(e[:, 0], 1.5 + math.pi * 0.4, rtol=1e-3)


def test_writeback_touches_only_its_own_attribute(empty_blend):
    bpy = empty_blend
    from addon import writeback

    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8)
    obj = bpy.context.active_object
    mat = bpy.data.materials.new("User material")
    obj.data.materials.append(mat)
    user_attr = obj.data.color_attributes.new("user_colors", "BYTE_COLOR", "CORNER")
    before_mesh = mesh_hash(obj.data)
    before_user = np.empty(len(user_attr.data) * 4, np.float32)
    user_attr.data.foreach_get("color", before_user)
    n = len(obj.data.vertices)
    colors = np.random.default_rng(0).random((n, 3)).astype(np.float32)
    writeback.write_colors(obj.data, colors)
    writeback.write_colors(obj.data, colors * 0.5)  # a second edit reuses the attribute
    attr = obj.data.color_attributes[writeback.ATTRIBUTE]
    got = np.empty(n * 4, np.float32)
    attr.data.foreach_get("color", got)
    np.testing.assert_allclose(got.reshape(n, 4)[:, :3], colors * 0.5, rtol=1e-6)
    assert mesh_hash(obj.data) == before_mesh
    after_user = np.empty_like(before_user)
    obj.data.color_attributes["user_colors"].data.foreach_get("color", after_user)
    np.testing.assert_array_equal(after_user, before_user)
    assert [m.name for m in obj.data.materials] == ["User material"]
    with pytest.raises(ValueError, match="shape"):
        writeback.write_colors(obj.data, colors[:-1])


def test_a_mirrored_object_exports_outward(empty_blend):
    # A negative scale mirrors the triangles' winding while Blender shades the object as
    # before; the export turns them back, so the core (which refuses an inward mesh) takes it
    # and a sun from above lights its top, as it does the unmirrored object.
    bpy = empty_blend
    from addon import export

    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(0.0, 0.0, 0.0))
    ball = bpy.context.active_object
    ball.scale = (-1.0, 1.0, 1.0)
    bpy.context.view_layer.update()
    before = mesh_hash(ball.data)
    scene, _ = export.export_scene([ball])
    scene.add_sun(direction=(0.0, 0.0, -1.0), irradiance=1.0)
    e = scene.irradiance()[:, 0]
    ball.scale = (1.0, 1.0, 1.0)
    bpy.context.view_layer.update()
    plain, _ = export.export_scene([ball])
    plain.add_sun(direction=(0.0, 0.0, -1.0), irradiance=1.0)
    assert e.max() > 0.5, "the top faces the sun"
    np.testing.assert_allclose(np.sort(e), np.sort(plain.irradiance()[:, 0]), atol=1e-5)
    assert mesh_hash(ball.data) == before, "export must not change the user's mesh"
