"""Light and shadow linking, and emissive meshes (issue 30 point 1), in headless Blender. A light
whose receiver collection leaves out the previewed object lights nothing of it directly in
Cycles; it still reaches it as the bounce of the objects it lights (Blender's rule: only included
objects -> those alone; only excluded -> all but those; none -> every object). What the export
cannot follow (an emitter whose emission cannot be read) is named in the panel, never silently
dropped; every method, the splatting included, follows the linking. Emissive meshes of any
shape, textured or hidden from shadow rays, light the preview."""

import numpy as np
import pytest

from helpers import key_light, mesh_hash, read_preview

pytestmark = pytest.mark.bpy


def _scene(bpy):
    """A 4 cm marble sphere (PRT, 8 coefficients) under the point light Key, a second point light
    Rim behind it, and a floor below it (an occluder). The medium is read at 250 mm per unit (a
    1 cm ball of marble): these tests check what lights it and what adds up, not the medium's
    scale, and the precompute's samples fall with the square of it (2.0 M -> 0.12 M)."""
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
    s.mm_per_unit = 250.0
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


def _same_light(bpy, mat, obj, emitter, a, b):
    """Asserts that previews `a` and `b` add the same light to the ball over the preview with
    `emitter` hidden from render (1e-3), and that `b` adds some (5 % of the brightest); returns
    that dark preview."""
    emitter.hide_render = True
    dark = _preview(bpy, mat, obj)
    emitter.hide_render = False
    assert np.abs(b - dark).max() > 0.05 * dark.max()  # the emitter lights the ball
    np.testing.assert_allclose(a - dark, b - dark, rtol=1e-3, atol=1e-4 * dark.max())
    return dark


def test_a_light_linked_away_from_the_ball_reaches_it_by_the_floor_alone(addon):
    # Cycles' light linking lights the receivers only, and each receiver sends that light on:
    # Rim lighting the floor alone reaches the ball only as the floor's bounce; lighting the
    # ball alone, only directly (the floor sends none of it back). The preview is linear in the
    # light (the dipole: no walks chosen by the light), so the two linked previews must add up
    # to the preview with Rim unlinked plus the one without Rim. Rim lighting nothing exported
    # is left out: the preview without it.
    import bpy

    from addon import export, panel, session

    mat, obj, rim = _scene(bpy)
    mat.translucent.profile = "DIPOLE"
    floor = bpy.data.objects["Floor"]
    with_rim = _preview(bpy, mat, obj)
    keys = export.lighting_keys(bpy.context.scene)
    rim.hide_render = True
    without_rim = _preview(bpy, mat, obj)
    assert np.abs(with_rim - without_rim).max() > 1e-3 * with_rim.max()  # Rim lights the ball
    rim.hide_render = False
    rim.light_linking.receiver_collection = _linking(bpy, "Rim on the floor", [(floor, "INCLUDE")])
    assert export.lighting_keys(bpy.context.scene) != keys  # following notices the change
    by_floor = _preview(bpy, mat, obj)
    # Only excluding the ball lights every other object: the same.
    rim.light_linking.receiver_collection = _linking(bpy, "Rim off the ball", [(obj, "EXCLUDE")])
    np.testing.assert_allclose(_preview(bpy, mat, obj), by_floor, rtol=1e-6, atol=1e-9)
    rim.light_linking.receiver_collection = _linking(bpy, "Rim on the ball", [(obj, "INCLUDE")])
    direct = _preview(bpy, mat, obj)
    np.testing.assert_allclose(by_floor + direct, with_rim + without_rim, rtol=1e-3, atol=1e-7)  # float sums
    assert np.abs(by_floor - without_rim).max() > 1e-3 * np.abs(with_rim - without_rim).max()  # the bounce
    sess = session.SESSIONS[mat.name]
    assert sess.info.unlinked_lights == [] and sess.info.lights == ["Key", "Rim"]
    assert sess.info.linking == []
    # Rim lighting only itself: nothing exported is lit by it.
    rim.light_linking.receiver_collection = _linking(bpy, "Rim on itself", [(rim, "INCLUDE")])
    np.testing.assert_allclose(_preview(bpy, mat, obj), without_rim, rtol=1e-6, atol=1e-9)
    sess = session.SESSIONS[mat.name]
    assert sess.info.unlinked_lights == ["Rim"] and sess.info.lights == ["Key"]
    assert "left out (light linking): Rim" in panel.summary(sess)
    assert sorted(bpy.data.collections.keys()) == ["Rim off the ball", "Rim on itself", "Rim on the ball",
                                                   "Rim on the floor"]


def test_the_splatting_follows_light_and_shadow_linking(addon):
    # The same scene splatted (Shah 2009): Rim left out of the ball's receivers puts no sample
    # on it in its light view, and reaches the ball by the floor's bounce alone (gathered at
    # the peeled crossings, light by light); Rim on the ball alone, its light view alone (the
    # floor unlit by it). The splatting is linear in the light, so the two add up to the
    # preview with Rim plus the one without. What the floor sends back is PRT's bounce on the
    # whole. (Shadow linking in the light views: `splat::tests::method` against the sun-lit
    # plane's closed form.)
    import bpy

    from addon import panel, session

    mat, obj, rim = _scene(bpy)
    mat.translucent.method = "SPLAT"
    mat.translucent.profile = "DIPOLE"
    with_rim = _preview(bpy, mat, obj)
    rim.hide_render = True
    without_rim = _preview(bpy, mat, obj)
    assert np.abs(with_rim - without_rim).max() > 1e-2 * with_rim.max()  # Rim lights the ball
    rim.hide_render = False
    rim.light_linking.receiver_collection = _linking(bpy, "Rim off the ball", [(obj, "EXCLUDE")])
    off_ball = _preview(bpy, mat, obj)
    rim.light_linking.receiver_collection = _linking(bpy, "Rim on the ball", [(obj, "INCLUDE")])
    on_ball = _preview(bpy, mat, obj)
    np.testing.assert_allclose(off_ball + on_ball, with_rim + without_rim, rtol=1e-3, atol=1e-7)
    sess = session.SESSIONS[mat.name]
    assert sess.method == "splat" and sess.info.linking == []
    assert not any("linking" in line for line, _ in panel.status_lines(mat))
    mat.translucent.method = "PRT"
    rim.light_linking.receiver_collection = _linking(bpy, "Rim off the ball (PRT)", [(obj, "EXCLUDE")])
    by_floor = _preview(bpy, mat, obj).sum(0)
    rim.hide_render = True
    bounce = by_floor - _preview(bpy, mat, obj).sum(0)
    ratio = (off_ball - without_rim).sum(0) / bounce
    assert np.all(bounce > 0) and np.all(np.abs(ratio - 1) < 0.1), ratio


def test_linking_follows_each_previewed_object(addon):
    # Two balls of one material (one mesh, two objects), Rim linked to one of them: Rim lighting
    # the ball and the floor (the second ball excluded), and Rim lighting the second ball alone,
    # add up to the preview with Rim unlinked plus the one without Rim, ball by ball (the dipole:
    # linear in the light). Then the second ball left out of Rim's blockers: it no longer
    # shadows the first from Rim, so the first ball brightens, and nothing darkens.
    import bpy

    from addon import session

    mat, obj, rim = _scene(bpy)
    mat.translucent.profile = "DIPOLE"
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.025, segments=16, ring_count=8, location=(0.0, 0.08, 0.0))
    other = bpy.context.active_object
    other.name = "Ball2"
    other.data.materials.append(mat)
    floor = bpy.data.objects["Floor"]

    def both():
        assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
        return read_preview(obj).copy(), read_preview(other).copy()

    with_rim = both()
    rim.hide_render = True
    without_rim = both()
    rim.hide_render = False
    rim.light_linking.receiver_collection = _linking(bpy, "Rim off Ball2", [(other, "EXCLUDE")])
    first = both()
    rim.light_linking.receiver_collection = _linking(bpy, "Rim on Ball2", [(other, "INCLUDE")])
    second = both()
    for k in range(2):
        np.testing.assert_allclose(first[k] + second[k], with_rim[k] + without_rim[k], rtol=1e-3, atol=1e-7)
    assert np.abs(second[1] - without_rim[1]).max() > 1e-2 * with_rim[1].max()  # Rim lights Ball2 ...
    assert np.abs(first[1] - with_rim[1]).max() > 1e-2 * with_rim[1].max()  # ... and only then
    assert session.SESSIONS[mat.name].info.linking == []
    rim.light_linking.receiver_collection = None
    rim.light_linking.blocker_collection = _linking(bpy, "Rim not blocked by Ball2", [(other, "EXCLUDE")])
    free = both()
    # Ball2's facets no longer shadow its own terminator either. Nothing darkens beyond the
    # floor's bounce noise: with Rim shadow-linked its bounce is found by cosine rays alone, not
    # also by paths from Rim (`irradiance`), so the two previews draw it differently (measured
    # 0.45 % of the brightest vertex at most).
    for k in range(2):
        assert np.all(free[k] >= with_rim[k] - 1e-2 * with_rim[k].max())
    assert np.abs(free[0] - with_rim[0]).max() > 1e-2 * with_rim[0].max()
    assert floor.data.materials[:] == []


def test_shadow_linking_lets_only_a_lights_blockers_cast_its_shadows(addon):
    # A black box between Rim and the ball (no bounce), Rim's blocker collection leaving it out:
    # Rim lights the ball unshadowed while the box still shadows Key. The preview is linear in
    # the lights (the dipole: no walks chosen by the light), so it must be Key's alone with the
    # box plus Rim's alone with no box at all.
    import bpy

    from addon import session

    mat, obj, rim = _scene(bpy)
    mat.translucent.profile = "DIPOLE"
    key = bpy.data.objects["Key"]
    black = bpy.data.materials.new("Black")
    black.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bpy.ops.mesh.primitive_cube_add(size=0.06, location=(0.0, 0.08, 0.03))
    box = bpy.context.active_object
    box.name = "Box"
    box.data.materials.append(black)
    for o in (key, rim, box, bpy.data.objects["Floor"]):
        o.data.materials.append(black) if o.type == "MESH" and not o.data.materials else None
    rim.hide_render = True
    key_alone = _preview(bpy, mat, obj)
    rim.hide_render, key.hide_render, box.visible_shadow = False, True, False
    rim_unshadowed = _preview(bpy, mat, obj)
    box.visible_shadow, key.hide_render = True, False
    rim_shadowed = _preview(bpy, mat, obj)
    key.hide_render = True
    rim_alone_shadowed = _preview(bpy, mat, obj)
    key.hide_render = False
    assert np.abs(rim_alone_shadowed - rim_unshadowed).max() > 1e-3  # the box does shadow Rim
    rim.light_linking.blocker_collection = _linking(bpy, "Rim blockers", [(box, "EXCLUDE")])
    linked = _preview(bpy, mat, obj)
    np.testing.assert_allclose(linked, key_alone + rim_unshadowed, rtol=1e-3, atol=1e-7)  # float sums
    assert np.abs(linked - rim_shadowed).max() > 1e-3
    sess = session.SESSIONS[mat.name]
    assert sess.info.linking == []
    # The ball, the only previewed object, left out of Rim's blockers too: followed (the mesh
    # casts none of Rim's shadows, `Scene.link_shadows(mesh=False)`, checked against the closed
    # form in the core's tests), so nothing is named as unfollowed. The faceted ball's own
    # facets then no longer shadow its terminator: only more light, somewhere.
    rim.light_linking.blocker_collection = _linking(bpy, "Rim blockers 2", [(obj, "EXCLUDE"), (box, "EXCLUDE")])
    free = _preview(bpy, mat, obj)
    assert np.all(free >= linked - 1e-5 * linked.max())
    assert np.abs(free - linked).max() > 3e-3 * linked.max()
    assert session.SESSIONS[mat.name].info.linking == []


def _emission(bpy, name, strength, colour=(1.0, 1.0, 1.0)):
    """A material whose only surface is an Emission shader of `strength` and `colour`."""
    mat = bpy.data.materials.new(name)
    tree = mat.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    emit = tree.nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = strength
    emit.inputs["Color"].default_value = (*colour, 1.0)
    tree.links.new(emit.outputs["Emission"], tree.nodes["Material Output"].inputs["Surface"])
    return mat


def test_emissive_meshes_light_as_area_lights_or_mesh_lights(addon):
    # An emissive rectangle (a softbox) is an area light on each side; any other emissive mesh
    # of one constant radiance is a mesh light (`Scene.add_mesh_light`, checked against closed
    # forms in the core and in tests/test_api.py), one hidden from shadow rays too (it shadows
    # nothing, not even its own far side). A Principled BSDF emits once its Emission Strength
    # is above 0 (Blender's default is 0) and its colour is not black.
    import bpy

    from addon import panel, session

    mat, obj, rim = _scene(bpy)
    bpy.ops.mesh.primitive_plane_add(size=0.1, location=(0.0, -0.2, 0.1))
    box = bpy.context.active_object
    box.name = "Softbox"
    box.data.materials.append(_emission(bpy, "Panel", 5.0))
    # Coarse spheres: a mesh light is sampled triangle by triangle (at 32 x 16 this test took
    # 194 s, at 8 x 4 131 s).
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.02, segments=8, ring_count=4, location=(0.15, 0.0, 0.0))
    orb = bpy.context.active_object
    orb.name = "Orb"
    orb.data.materials.append(_emission(bpy, "Glow", 3.0, (1.0, 0.5, 0.2)))
    glow = bpy.data.materials.new("Floor glow")
    bsdf = glow.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Emission Color"].default_value = (1.0, 0.5, 0.2, 1.0)
    floor = bpy.data.objects["Floor"]
    floor.data.materials.append(glow)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.01, segments=8, ring_count=4, location=(-0.15, 0.0, 0.0))
    ghost = bpy.context.active_object
    ghost.name = "Ghost"
    ghost.visible_shadow = False  # no shadow, still a light in Cycles
    ghost.data.materials.append(bpy.data.materials["Glow"])
    _preview(bpy, mat, obj)
    info = session.SESSIONS[mat.name].info
    assert info.emitters == [], info.emitters
    assert "Softbox (emissive rectangle)" in info.lights and "Orb (emissive mesh)" in info.lights, info.lights
    assert "Ghost (emissive mesh, hidden from shadow rays)" in info.lights, info.lights
    lines = [text for text, _ in panel.status_lines(mat)]
    assert not [t for t in lines if "emits light in Cycles that the preview does not have" in t], lines
    # The Orb's light is linear in its Strength: twice it adds twice as much to the ball (the
    # dipole: no walks chosen by the light).
    mat.translucent.profile = "DIPOLE"
    glow_node = bpy.data.materials["Glow"].node_tree.nodes["Emission"]
    glow_node.inputs["Strength"].default_value = 0.0
    ghost.hide_render = True  # it shares the material: only the Orb is left to change
    dark = _preview(bpy, mat, obj)
    glow_node.inputs["Strength"].default_value = 3.0
    once = _preview(bpy, mat, obj)
    glow_node.inputs["Strength"].default_value = 6.0
    twice = _preview(bpy, mat, obj)
    assert np.abs(once - dark).max() > 1e-3 * dark.max()
    np.testing.assert_allclose(twice - dark, 2.0 * (once - dark), rtol=1e-3, atol=1e-6 * dark.max())
    ghost.hide_render = False
    glow_node.inputs["Strength"].default_value = 3.0
    assert np.abs(_preview(bpy, mat, obj) - once).max() > 1e-3 * once.max()  # the Ghost lights the ball
    bsdf.inputs["Emission Strength"].default_value = 2.0
    _preview(bpy, mat, obj)
    assert "Floor (emissive rectangle)" in session.SESSIONS[mat.name].info.lights
    bsdf.inputs["Emission Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    _preview(bpy, mat, obj)
    assert "Floor (emissive rectangle)" not in session.SESSIONS[mat.name].info.lights


def _half_glowing(bpy, name, strength, below: bool = False):
    """An Emission material whose Strength is `strength` where the object's own Z is above 0
    (below it with `below`) and 0 elsewhere, through nodes: a textured emission, read by
    Cycles' bake."""
    mat = _emission(bpy, name, strength)
    tree = mat.node_tree
    coords = tree.nodes.new("ShaderNodeTexCoord")
    xyz = tree.nodes.new("ShaderNodeSeparateXYZ")
    side = tree.nodes.new("ShaderNodeMath")
    side.operation = "LESS_THAN" if below else "GREATER_THAN"
    side.inputs[1].default_value = 0.0
    scale = tree.nodes.new("ShaderNodeMath")
    scale.operation = "MULTIPLY"
    scale.inputs[1].default_value = strength
    tree.links.new(coords.outputs["Object"], xyz.inputs[0])
    tree.links.new(xyz.outputs["Z"], side.inputs[0])
    tree.links.new(side.outputs[0], scale.inputs[0])
    tree.links.new(scale.outputs[0], tree.nodes["Emission"].inputs["Strength"])
    return mat


def test_a_textured_emission_lights_where_cycles_says_it_glows(addon):
    # A lamp sphere beside the ball whose Emission Strength is 60 on its upper half and 0 below,
    # through nodes (Object Z > 0): Cycles' emission pass is baked at its face corners and the
    # lamp is a mesh light of that radiance. Its faces split into two material slots instead,
    # the upper ones a constant Emission of 60 and the lower ones of 0, is the constant path
    # (checked against closed forms): the same light, to float rounding. The corners must be
    # read where they are: any other mapping lights other faces. The lower half glowing instead
    # lights the ball differently, and a change of the nodes changes what following compares.
    import bpy

    from addon import export, panel, session

    mat, obj, rim = _scene(bpy)
    mat.translucent.profile = "DIPOLE"
    rim.hide_render = True
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.03, segments=24, ring_count=12, location=(0.12, 0.0, 0.02))
    lamp = bpy.context.active_object
    lamp.name = "Lamp"
    lamp.rotation_euler = (0.7, 0.0, 0.3)  # its own Z tilted toward the ball
    textured = _half_glowing(bpy, "Half glow", 60.0)
    lamp.data.materials.append(textured)
    before = (mesh_hash(lamp.data), textured.node_tree.nodes["Math"].inputs[1].default_value, textured.users,
              len(bpy.data.meshes), len(bpy.data.objects), len(bpy.data.scenes))
    by_texture = _preview(bpy, mat, obj)
    # The bake's copies are gone and the lamp's own data only read.
    assert (mesh_hash(lamp.data), textured.node_tree.nodes["Math"].inputs[1].default_value, textured.users,
            len(bpy.data.meshes), len(bpy.data.objects), len(bpy.data.scenes)) == before
    info = session.SESSIONS[mat.name].info
    assert "Lamp (emissive mesh, textured)" in info.lights and info.emitters == [], (info.lights, info.emitters)
    lines = [text for text, _ in panel.status_lines(mat)]
    assert any("Lamp: emission read by Cycles at" in t for t in lines), lines
    keys = export.occluder_keys(bpy.context.evaluated_depsgraph_get(), {obj.name})
    assert keys == info.occluder_keys
    textured.node_tree.nodes["Math"].inputs[1].default_value = 0.01  # the threshold moved: bake again
    assert export.occluder_keys(bpy.context.evaluated_depsgraph_get(), {obj.name}) != keys
    textured.node_tree.nodes["Math"].inputs[1].default_value = 0.0
    # The same light through material slots.
    lamp.data.materials.clear()
    lamp.data.materials.append(_emission(bpy, "Glow 60", 60.0))
    lamp.data.materials.append(_emission(bpy, "Glow 0", 0.0))
    upper = np.array([p.center.z > 0.0 for p in lamp.data.polygons])
    lamp.data.polygons.foreach_set("material_index", np.where(upper, 0, 1).astype(np.int32))
    lamp.data.update()
    dark = _same_light(bpy, mat, obj, lamp, by_texture, _preview(bpy, mat, obj))
    lamp.data.materials.clear()
    lamp.data.materials.append(_half_glowing(bpy, "Lower glow", 60.0, below=True))
    lower = _preview(bpy, mat, obj)
    assert np.abs((lower - dark) - (by_texture - dark)).max() > 0.05 * (by_texture - dark).max()


def test_an_instances_textured_emission_lights_as_the_object_placed_there(addon):
    # A lamp glowing (60) where the world's Z lies above 2 cm, through nodes (Geometry
    # Position), kept in a collection of its own (not in the scene) and instanced by an Empty
    # turned and moved beside the ball: Cycles' emission pass is baked on a copy of the lamp's
    # mesh placed at the instance. Its corners glow where the instance's surface lies above
    # 2 cm (at the lamp's own place, the origin, only a cap would), and the instance lights the
    # ball as the lamp itself placed there does (the object's path, checked against constant
    # slots above).
    import bpy

    from addon import panel, session

    mat, obj, rim = _scene(bpy)
    mat.translucent.profile = "DIPOLE"
    rim.hide_render = True
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.03, segments=24, ring_count=12)
    lamp = bpy.context.active_object
    lamp.name = "Lamp"
    glow = _half_glowing(bpy, "Half glow", 60.0)
    tree = glow.node_tree
    position = tree.nodes.new("ShaderNodeNewGeometry")
    tree.links.new(position.outputs["Position"], tree.nodes["Separate XYZ"].inputs[0])
    tree.nodes["Math"].inputs[1].default_value = 0.02
    lamp.data.materials.append(glow)
    lamps = bpy.data.collections.new("Lamps")
    for c in list(lamp.users_collection):
        c.objects.unlink(lamp)
    lamps.objects.link(lamp)
    empty = bpy.data.objects.new("Lamp instance", None)
    empty.instance_type = "COLLECTION"
    empty.instance_collection = lamps
    empty.location = (0.12, 0.0, 0.02)
    empty.rotation_euler = (0.7, 0.0, 0.3)
    bpy.context.scene.collection.objects.link(empty)
    before = (mesh_hash(lamp.data), tuple(lamp.matrix_world.translation), len(bpy.data.meshes),
              len(bpy.data.objects), len(bpy.data.scenes))
    instanced = _preview(bpy, mat, obj)
    assert (mesh_hash(lamp.data), tuple(lamp.matrix_world.translation), len(bpy.data.meshes),
            len(bpy.data.objects), len(bpy.data.scenes)) == before
    info = session.SESSIONS[mat.name].info
    assert "Lamp (emissive mesh, textured)" in info.lights and info.emitters == [], (info.lights, info.emitters)
    lines = [text for text, _ in panel.status_lines(mat)]
    assert any("Lamp: emission read by Cycles at" in t for t in lines), lines
    (light,) = info.emissive_meshes  # the triangles with a glowing corner
    z = light.positions[light.triangles][..., 2]
    agree = ((light.corners[..., 0] > 30.0) == (z > 0.02)).mean()  # corners on the line may go either way
    assert agree > 0.97, agree
    # The lamp itself where the instance was.
    bpy.context.scene.collection.objects.unlink(empty)
    lamps.objects.unlink(lamp)
    bpy.context.scene.collection.objects.link(lamp)
    lamp.matrix_world = empty.matrix_world
    _same_light(bpy, mat, obj, lamp, instanced, _preview(bpy, mat, obj))


def _glowing_points(bpy, glow, realize: bool):
    """A one-vertex object at (0.1, 0, 0.02) whose geometry nodes instance a 1.5 cm ico sphere
    there in the material `glow` (Set Material: the instance's own, in no slot of the object),
    realized into the object's own mesh with `realize`."""
    mesh = bpy.data.meshes.new("Point")
    mesh.from_pydata([(0.0, 0.0, 0.0)], [], [])
    host = bpy.data.objects.new("Host", mesh)
    host.location = (0.1, 0.0, 0.02)
    bpy.context.scene.collection.objects.link(host)
    group = bpy.data.node_groups.new("Glowing points", "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = group.nodes, group.links
    given, out = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    ico = nodes.new("GeometryNodeMeshIcoSphere")
    ico.inputs["Radius"].default_value = 0.015
    ico.inputs["Subdivisions"].default_value = 2
    material = nodes.new("GeometryNodeSetMaterial")
    material.inputs["Material"].default_value = glow
    on_points = nodes.new("GeometryNodeInstanceOnPoints")
    links.new(ico.outputs["Mesh"], material.inputs["Geometry"])
    links.new(given.outputs[0], on_points.inputs["Points"])
    links.new(material.outputs[0], on_points.inputs["Instance"])
    result = on_points.outputs[0]
    if realize:
        realized = nodes.new("GeometryNodeRealizeInstances")
        links.new(result, realized.inputs[0])
        result = realized.outputs[0]
    links.new(result, out.inputs[0])
    host.modifiers.new("Glowing points", "NODES").node_group = group
    return host


def test_geometry_nodes_instances_emit_by_their_own_material(addon):
    # Geometry nodes instance an ico sphere whose Set Material gives it an Emission the object
    # holds in none of its slots: the instance is lit by that material (it was read from the
    # object's slots, and the light dropped unseen), as the same sphere realized into the
    # object's own mesh is. A textured emission on such an instance (geometry no object holds,
    # so no copy to bake) keeps its faces as shadow and bounce and is named in the panel.
    import bpy

    from addon import panel, session

    mat, obj, rim = _scene(bpy)
    mat.translucent.profile = "DIPOLE"
    rim.hide_render = True
    glow = _emission(bpy, "Glow 40", 40.0)
    host = _glowing_points(bpy, glow, realize=False)
    instanced = _preview(bpy, mat, obj)
    info = session.SESSIONS[mat.name].info
    assert "Host (emissive mesh)" in info.lights and info.emitters == [], (info.lights, info.emitters)
    bpy.data.objects.remove(host)
    host = _glowing_points(bpy, glow, realize=True)
    _same_light(bpy, mat, obj, host, instanced, _preview(bpy, mat, obj))
    bpy.data.objects.remove(host)
    host = _glowing_points(bpy, _half_glowing(bpy, "Half glow", 40.0), realize=False)
    _preview(bpy, mat, obj)
    info = session.SESSIONS[mat.name].info
    assert info.emitters == ["Host"] and "Host (emissive mesh, textured)" not in info.lights, info.lights
    lines = [text for text, _ in panel.status_lines(mat)]
    assert sum("Host: an instance's emission was not read" in t for t in lines) == 1, lines
    assert any("Host: emits light in Cycles that the preview does not have" in t for t in lines), lines


def test_an_emissive_rectangle_lights_as_cycles_lights_it(addon):
    # Cycles itself says how an emissive rectangle's Strength S compares with an area light's
    # Power: a white diffuse grid baked under a 10 cm emissive square of S = 20 and under a
    # 10 cm square area light of P = pi A S in its place gives the same light (64 spp, within
    # 3 % on the whole). The preview of a marble ball under the square is then the preview under
    # that area light (the rectangle, an occluder too, does not shadow its own light).
    import bpy
    import math

    from blender_scripts.lib.cycles_reference import bake_diffuse_vertex_colors, use_cycles

    bpy.ops.mesh.primitive_grid_add(x_subdivisions=10, y_subdivisions=10, size=0.4)
    grid = bpy.context.active_object
    grid.data.materials.append(bpy.data.materials.new("White"))
    grid.data.materials[0].node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (1, 1, 1, 1)
    bpy.ops.mesh.primitive_plane_add(size=0.1, location=(0.02, 0.0, 0.15))
    square = bpy.context.active_object
    square.data.materials.append(_emission(bpy, "Softbox", 20.0))
    use_cycles(64, 0)
    under_square = bake_diffuse_vertex_colors(grid, {"DIRECT", "COLOR"})
    square.hide_render = True
    lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "AREA"))
    lamp.data.shape, lamp.data.size = "SQUARE", 0.1
    lamp.data.energy = math.pi * 0.1 * 0.1 * 20.0
    lamp.location = (0.02, 0.0, 0.15)  # a Blender area light shines along its -Z: down
    bpy.context.scene.collection.objects.link(lamp)
    under_lamp = bake_diffuse_vertex_colors(grid, {"DIRECT", "COLOR"})
    ratio = under_square.sum(axis=0) / under_lamp.sum(axis=0)
    print(f"Cycles: emissive square / area light of pi A S: {ratio}")
    np.testing.assert_allclose(ratio, 1.0, atol=0.03)
    # The preview: the grid a marble ball now, under the square, then under the lamp alone.
    bpy.data.objects.remove(grid)
    s = bpy.data.materials.new("Wax").translucent
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.04, segments=16, ring_count=8)
    ball = bpy.context.active_object
    ball.data.materials.append(bpy.data.materials["Wax"])
    s.enabled, s.preset, s.coefficients, s.method = True, "MARBLE", 8, "PRT"
    wax = bpy.data.materials["Wax"]
    lit_by_lamp = _preview(bpy, wax, ball)
    lamp.hide_render, square.hide_render = True, False
    lit_by_square = _preview(bpy, wax, ball)
    assert np.abs(lit_by_square).max() > 0.0
    # Within the light's lift off the square (a thousandth of its size, 15 cm away: 0.1 %), as
    # area-weighted relative RMS (a few vertices by the shadow's edge move by up to 3 %).
    import translucent
    from addon import export

    areas = export.export_scene([ball])[0].vertex_areas
    rms = max(translucent.relative_error(lit_by_square, lit_by_lamp, areas)["rms"])
    print(f"preview under the square against under the area light: {100 * rms:.3f} %")
    assert rms < 5e-3


def test_a_textured_lamp_lights_a_grid_as_cycles_does(addon):
    # A white Diffuse BSDF grid under a 3 cm sphere lamp whose Emission Color is a Checker
    # Texture of two colours (Object coordinates, tilted): Cycles' diffuse bake (direct light
    # times colour: E / pi for a white Diffuse BSDF, 256 spp) against the irradiance the export
    # hands the native module for the grid (`Scene.irradiance`, 1024 samples of the lamp) over
    # pi, per vertex. The same with the lamp hidden from shadow rays, where Cycles sees its far
    # side through its near one: read as hidden, the preview would have half of it. The
    # preview's corners blend the checker across the faces a square's edge crosses. Measured:
    # on the whole 0.996-1.001 (shadowed) and 1.009-1.013 (not), RMS 2.7 / 1.2 / 2.6 % and
    # 3.3 / 2.8 / 3.1 % (green, the same in both squares, is the two estimates' noise).
    import bpy

    from addon import export
    from blender_scripts.lib.cycles_reference import bake_diffuse_vertex_colors, use_cycles

    bpy.ops.mesh.primitive_grid_add(x_subdivisions=20, y_subdivisions=20, size=0.4)
    grid = bpy.context.active_object
    white = bpy.data.materials.new("White")
    tree = white.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    tree.links.new(diffuse.outputs["BSDF"], tree.nodes["Material Output"].inputs["Surface"])
    grid.data.materials.append(white)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.03, segments=32, ring_count=16, location=(0.03, 0.02, 0.08))
    lamp = bpy.context.active_object
    lamp.rotation_euler = (0.5, 0.3, 0.0)
    glow = _emission(bpy, "Checker glow", 20.0)
    checker = glow.node_tree.nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 12.0
    checker.inputs["Color1"].default_value = (1.0, 0.3, 0.1, 1.0)
    checker.inputs["Color2"].default_value = (0.1, 0.3, 1.0, 1.0)
    coords = glow.node_tree.nodes.new("ShaderNodeTexCoord")
    glow.node_tree.links.new(coords.outputs["Object"], checker.inputs["Vector"])
    glow.node_tree.links.new(checker.outputs["Color"], glow.node_tree.nodes["Emission"].inputs["Color"])
    lamp.data.materials.append(glow)
    use_cycles(256, 0)
    areas = None
    for shadow in (True, False):
        lamp.visible_shadow = shadow
        cycles = bake_diffuse_vertex_colors(grid, {"DIRECT", "COLOR"})
        scene, info = export.export_scene([grid])
        assert any("emissive mesh, textured" in line for line in info.lights), info.lights
        preview = np.asarray(scene.irradiance(eta=1.0, area_samples=1024)) / np.pi
        areas = np.asarray(scene.vertex_areas)[:, :1] if areas is None else areas
        rms = np.sqrt((areas * (preview - cycles) ** 2).sum(0) / (areas * cycles**2).sum(0))
        ratio = (areas * preview).sum(0) / (areas * cycles).sum(0)
        print(f"visible_shadow {shadow}: preview / Cycles on the whole {ratio}, area-weighted relative RMS {rms}")
        assert np.all(np.abs(ratio - 1.0) < 0.03), ratio
        assert np.all(rms < 0.05), rms


def test_glowing_faces_of_another_material_on_the_ball_light_it(addon):
    # A 1 cm bulb beside the ball, part of the ball's own mesh, in a second material, an
    # Emission (a lantern's bulb): its faces are a mesh light of their own (not previewed),
    # lighting the ball and the floor that sends it back, and named nowhere as unfollowed. The
    # light is linear in their Strength (the dipole: no walks chosen by the light); a change of
    # it changes what following compares.
    import bpy

    from addon import export, session

    mat, obj, rim = _scene(bpy)
    mat.translucent.profile = "DIPOLE"
    bulb = _emission(bpy, "Bulb", 0.0)
    obj.data.materials.append(bulb)
    bpy.ops.mesh.primitive_ico_sphere_add(radius=0.01, subdivisions=2, location=(0.07, -0.03, 0.02))
    lamp = bpy.context.active_object
    lamp.data.materials.append(bulb)
    bpy.ops.object.select_all(action="DESELECT")
    lamp.select_set(True)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.join()  # the bulb's faces keep their material, now the Ball's second slot
    dark = _preview(bpy, mat, obj)
    bulb.node_tree.nodes["Emission"].inputs["Strength"].default_value = 40.0
    keys = session.SESSIONS[mat.name].info.occluder_keys
    assert export.occluder_keys(bpy.context.evaluated_depsgraph_get(), {obj.name}) != keys
    once = _preview(bpy, mat, obj)
    info = session.SESSIONS[mat.name].info
    assert "Ball (emissive mesh)" in info.lights and info.emitters == [], (info.lights, info.emitters)
    assert export.occluder_keys(bpy.context.evaluated_depsgraph_get(), {obj.name}) == info.occluder_keys
    bulb.node_tree.nodes["Emission"].inputs["Strength"].default_value = 80.0
    twice = _preview(bpy, mat, obj)
    assert np.abs(once - dark).max() > 0.01 * dark.max()
    np.testing.assert_allclose(twice - dark, 2.0 * (once - dark), rtol=1e-3, atol=1e-5 * dark.max())


def test_an_emission_whose_bake_fails_keeps_its_constant_faces_and_is_named(addon, monkeypatch):
    # A lamp whose upper faces glow through nodes and whose lower faces glow a constant
    # Emission: read whole by Cycles' bake, one textured mesh light. Where the bake fails (made
    # to fail here), the constant faces are still a light, and the lamp is named in the panel
    # as emitting more than the preview has.
    import bpy

    from addon import emission, panel, session

    mat, obj, rim = _scene(bpy)
    mat.translucent.profile = "DIPOLE"
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.02, segments=16, ring_count=8, location=(0.1, 0.0, 0.02))
    lamp = bpy.context.active_object
    lamp.name = "Lamp"
    lamp.data.materials.append(_half_glowing(bpy, "Half glow", 30.0))
    lamp.data.materials.append(_emission(bpy, "Glow 30", 30.0))
    lower = np.array([p.center.z < 0.0 for p in lamp.data.polygons])
    lamp.data.polygons.foreach_set("material_index", lower.astype(np.int32))
    lamp.data.update()
    _preview(bpy, mat, obj)
    info = session.SESSIONS[mat.name].info
    assert "Lamp (emissive mesh, textured)" in info.lights and info.emitters == [], (info.lights, info.emitters)

    def fail(*_a, **_k):
        raise ValueError("made to fail")

    monkeypatch.setattr(emission, "corner_radiance", fail)
    _preview(bpy, mat, obj)
    info = session.SESSIONS[mat.name].info
    assert "Lamp (emissive mesh)" in info.lights and info.emitters == ["Lamp"], (info.lights, info.emitters)
    lines = [text for text, _ in panel.status_lines(mat)]
    assert any("Lamp: its emission was not read (made to fail)" in t for t in lines), lines
    assert any("Lamp: emits light in Cycles that the preview does not have" in t for t in lines), lines
