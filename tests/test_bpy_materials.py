"""Several materials on one object (issue 30 point 3), in headless Blender: only the faces of the
previewed material receive the preview and the object's faces of other materials are written
nothing; an object holding the material on no face is left out, saying so. Expected values, from
closed forms independent of the code under test:
- a preset material (not read from the Principled BSDF): the other faces cast shadows only, so
  light enters only through the previewed half of a sun-lit plane and a vertex at a distance d
  from the other half gathers E_in (R_total - H(d)) (the dipole's half-plane integral,
  helpers.half_plane, from its closed-form disc integral);
- a material read from its Principled BSDF (PRT): the other faces stay in the mesh as Cycles'
  walk sees them (it leaves its object through a face of any material, shaded there with a
  diffuse lobe), so the light entering the other half reaches the previewed one and a vertex
  gathers the whole plane's E_in R_total, up to the seam."""

import numpy as np
import pytest

from helpers import assert_own_half_plane, entering, half_plane, mesh_hash, rd_total, read_preview

pytestmark = pytest.mark.bpy


def two_material_plane(bpy):
    """A 40 cm grid (81 x 81 vertices, 5 mm apart) under a sun straight down: faces with x < 0
    in the marble material "Wax" (dipole), faces with x > 0 in an opaque "Paint"."""
    wax, paint = bpy.data.materials.new("Wax"), bpy.data.materials.new("Paint")
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=80, y_subdivisions=80, size=0.4)
    obj = bpy.context.active_object
    obj.data.materials.append(wax)
    obj.data.materials.append(paint)
    centres = np.empty(len(obj.data.polygons) * 3, np.float32)
    obj.data.polygons.foreach_get("center", centres)
    obj.data.polygons.foreach_set("material_index", (centres.reshape(-1, 3)[:, 0] > 0).astype(np.int32))
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = 3.0
    bpy.context.scene.collection.objects.link(sun)
    s = wax.translucent
    s.enabled = True
    s.preset = "MARBLE"
    s.profile = "DIPOLE"
    s.coefficients = 16
    return wax, paint, obj


def seam_grids(bpy, materials):
    """Two 20 x 40 cm grids (41 x 81 vertices) meeting at x = 0, the left in materials[0], the
    right in materials[1], under a sun straight down (3 W/m^2): the two objects."""
    objs = []
    for x, mat in zip((-0.1, 0.1), materials):
        bpy.ops.mesh.primitive_grid_add(x_subdivisions=40, y_subdivisions=80, size=0.2, location=(x, 0.0, 0.0))
        obj = bpy.context.active_object
        obj.scale.y = 2.0
        obj.data.materials.append(mat)
        objs.append(obj)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = 3.0
    bpy.context.scene.collection.objects.link(sun)
    return objs


def test_only_the_previewed_faces_scatter_and_the_rest_keep_their_colours(addon):
    import bpy

    from addon import session, writeback

    wax, paint, obj = two_material_plane(bpy)
    user_mesh = mesh_hash(obj.data)
    # What the user painted in the attribute before (or an earlier preview) on every vertex.
    before = np.tile(np.array([0.1, 0.2, 0.3], np.float32), (len(obj.data.vertices), 1))
    writeback.write_colors(obj.data, before)
    assert bpy.ops.translucent.precompute(material_name=wax.name) == {"FINISHED"}
    sess = session.SESSIONS[wax.name]
    co = np.array([v.co for v in obj.data.vertices])
    faces = np.array([v for f in obj.data.polygons if f.material_index == 0 for v in f.vertices])
    covered = np.zeros(len(co), bool)
    covered[faces] = True
    assert sess.transport.vertex_count == covered.sum() == 41 * 81
    assert sess.info.occluders == [f"{obj.name} [other materials]"]
    now = read_preview(obj)
    np.testing.assert_array_equal(now[~covered], before[~covered])  # the paint's vertices untouched
    # The covered vertices show the transport's radiance, vertex for vertex.
    m = wax.translucent.material()
    r = sess.info.objects[0]
    np.testing.assert_allclose(now[r.vertices], sess.transport.radiance(m), rtol=1e-6)
    assert not np.allclose(now[covered], before[covered])
    # The physics: light enters through the wax half only.
    b = np.full((len(co), 3), np.nan)
    b[r.vertices] = sess.transport.radiosity(m)
    e_in = entering(m.eta, 1.0, 3.0)
    row = np.flatnonzero(np.abs(co[:, 1]) < 1e-6)
    assert assert_own_half_plane(b, co, m, e_in, keep=lambda x: x < 0) > 60  # the paint's side: none
    # Next to the paint, less comes back than far from it (the light lost under the paint).
    assert b[row[np.argmin(np.abs(co[row, 0] + 0.005))], 0] < 0.97 * e_in * rd_total(
        m.sigma_a[0], (1 - m.g) * m.sigma_s[0], m.eta)
    assert mesh_hash(obj.data) == user_mesh
    assert [s.material for s in obj.material_slots] == [wax, paint]


def test_faces_of_another_material_let_light_in_as_cycles_walk_leaves_through_them(addon):
    import bpy

    from addon import session

    wax, paint, obj = two_material_plane(bpy)
    s = wax.translucent
    s.source = "PRINCIPLED"
    p = wax.node_tree.nodes["Principled BSDF"]
    p.inputs["Subsurface Weight"].default_value = 1.0
    p.inputs["Subsurface Scale"].default_value = 0.005
    p.inputs["Base Color"].default_value = (0.8, 0.6, 0.5, 1.0)
    paint.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.3, 0.3, 0.3, 1.0)
    before = np.tile(np.array([0.1, 0.2, 0.3], np.float32), (len(obj.data.vertices), 1))
    from addon import writeback

    writeback.write_colors(obj.data, before)
    user_mesh = mesh_hash(obj.data)
    assert bpy.ops.translucent.precompute(material_name=wax.name) == {"FINISHED"}
    sess = session.SESSIONS[wax.name]
    assert sess.transport.vertex_count == len(obj.data.vertices) and sess.info.occluders == []
    co = np.array([v.co for v in obj.data.vertices])
    covered = np.zeros(len(co), bool)
    covered[[v for f in obj.data.polygons if f.material_index == 0 for v in f.vertices]] = True
    r = sess.info.objects[0]
    np.testing.assert_array_equal(np.isnan(r.others[:, 0]), covered)
    np.testing.assert_allclose(r.others[~covered], 0.3, rtol=1e-6)  # the paint's own albedo
    now = read_preview(obj)
    np.testing.assert_array_equal(now[~covered], before[~covered])  # the paint's vertices untouched
    assert "vertices of other materials scatter as their own colour" in sess.texture_message
    assert not sess.edit_message, sess.edit_message
    m = wax.translucent.material()
    # A uniform material: the paint's albedo passed apart (`others=`), the wax's vertices a
    # uniform edit, the paint's NaN.
    assert sess.base_color is None
    np.testing.assert_array_equal(np.isnan(sess.others[:, 0]), covered)
    b = sess.transport.radiosity(m, others=sess.others)
    assert np.isnan(b[~covered]).all()
    np.testing.assert_allclose(now[covered], sess.transport.radiance(m, others=sess.others)[covered], rtol=1e-6)
    e_in = entering(m.eta, 1.0, 3.0)
    checked = 0
    for c in range(3):
        total = e_in * rd_total(m.sigma_a[c], (1 - m.g) * m.sigma_s[c], m.eta)
        for v in np.flatnonzero((np.abs(co[:, 1]) < 1e-6) & (co[:, 0] < 1e-6) & (co[:, 0] > -0.12)):
            # The whole plane's light, up to the seam itself (x = 0).
            assert abs(b[v, c] / total - 1) < 0.02, (c, co[v, 0], b[v, c] / total)
            checked += 1
    assert checked > 60
    # The half-plane answer (light through the wax alone) is about half of it at the seam.
    assert half_plane(m, 0, 0.0) > 0.4 * rd_total(m.sigma_a[0], (1 - m.g) * m.sigma_s[0], m.eta)
    # A Base Color edit of the previewed material reads the colours again: the paint's stay.
    p.inputs["Base Color"].default_value = (0.7, 0.6, 0.5, 1.0)
    bpy.context.view_layer.update()
    from addon import edits

    edits.follow_principled(bpy.context.scene, bpy.context.evaluated_depsgraph_get())
    assert sess.base_color is None and sess.transport is not None
    np.testing.assert_allclose(sess.others[~covered], 0.3, rtol=1e-6)
    # The paint's colour changed: read at once, on the same transport (no precompute), and the
    # preview is that transport's answer for the new colours.
    transport, shown = sess.transport, read_preview(obj)
    paint.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.6, 0.5, 0.4, 1.0)
    bpy.context.view_layer.update()
    edits.follow_principled(bpy.context.scene, bpy.context.evaluated_depsgraph_get())
    assert sess.transport is transport and not sess.edit_message, sess.edit_message
    np.testing.assert_allclose(sess.others[~covered], np.tile([0.6, 0.5, 0.4], ((~covered).sum(), 1)), rtol=1e-6)
    m = wax.translucent.material()
    colours = np.where(covered[:, None], np.float32([0.7, 0.6, 0.5]), np.float32([0.6, 0.5, 0.4]))
    after = read_preview(obj)
    others = np.where(covered[:, None], np.float32(np.nan), colours).astype(np.float32)
    np.testing.assert_allclose(after[covered], transport.radiance(m, others=others)[covered], rtol=1e-5)
    # The per-vertex edit with both colours in its rows agrees (its table interpolates the wax's).
    np.testing.assert_allclose(after[covered], transport.radiance(m, base_color=colours.astype(np.float32))[covered],
                               rtol=1e-2, atol=1e-6)
    # A walk that starts in the wax takes the wax's albedo wherever it leaves, and a flat plane
    # sends itself no light: the wax's preview stays as it was.
    np.testing.assert_allclose(after[covered], shown[covered], rtol=1e-6)
    np.testing.assert_array_equal(after[~covered], before[~covered])  # still untouched
    assert mesh_hash(obj.data) == user_mesh
    assert [s.material for s in obj.material_slots] == [wax, paint]


def test_a_new_attribute_shows_the_uncovered_vertices_in_the_default_grey(addon):
    import bpy

    from addon import writeback

    wax, _, obj = two_material_plane(bpy)
    assert bpy.ops.translucent.precompute(material_name=wax.name) == {"FINISHED"}
    paint_only = np.ones(len(obj.data.vertices), bool)
    paint_only[[v for f in obj.data.polygons if f.material_index == 0 for v in f.vertices]] = False
    np.testing.assert_array_equal(read_preview(obj)[paint_only], np.tile(np.float32(writeback.UNCOVERED), (paint_only.sum(), 1)))


def test_an_object_holding_the_material_on_no_face_is_left_out_saying_so(addon):
    import bpy

    from addon import panel, session

    wax, paint, obj = two_material_plane(bpy)
    bpy.ops.mesh.primitive_cube_add(size=0.05, location=(0.0, 0.0, -0.3))
    cube = bpy.context.active_object
    cube.data.materials.append(paint)
    cube.data.materials.append(wax)  # in a slot, on no face
    assert bpy.ops.translucent.precompute(material_name=wax.name) == {"FINISHED"}
    sess = session.SESSIONS[wax.name]
    assert sess.objects == [obj.name] and sess.info.without_faces == [cube.name]
    assert f"{cube.name} holding it on no face left out" in panel.summary(sess)
    assert "translucent_preview" not in cube.data.color_attributes
    # Not taken for an object that took the material since.
    bpy.context.view_layer.update()
    from addon import follow

    follow.follow_now()
    assert session.state(wax) == "ready"
    # Only a cube holding it and no plane: a clear error naming the cube.
    bpy.data.objects.remove(obj)
    with pytest.raises(RuntimeError, match=f"{cube.name} hold it in a slot but on none of their faces"):
        bpy.ops.translucent.precompute(material_name=wax.name)


def test_assigning_more_faces_to_the_material_refreshes_the_preview(addon):
    import bpy

    from addon import follow, session

    wax, paint, obj = two_material_plane(bpy)
    assert bpy.ops.translucent.precompute(material_name=wax.name) == {"FINISHED"}
    first = session.SESSIONS[wax.name]
    idx = np.zeros(len(obj.data.polygons), np.int32)  # every face in the wax now
    obj.data.polygons.foreach_set("material_index", idx)
    obj.data.update()
    bpy.context.view_layer.update()
    follow.follow_now()
    sess = session.SESSIONS[wax.name]
    assert sess is not first and sess.transport.vertex_count == len(obj.data.vertices)
    assert np.all(read_preview(obj).sum(axis=1) > 0)


def test_two_touching_objects_of_different_materials_exchange_no_light(addon):
    # Issue 30 point 4: two grids meeting at x = 0, marble on the left, skin on the right, both
    # previewed, each with its own settings. Each is the other's occluder and never its medium:
    # the marble's vertices gather only what entered the marble (E_in (R_total - H(d))), and
    # previewing the skin changes nothing of the marble's preview.
    import bpy

    from addon import session

    left_mat, right_mat = bpy.data.materials.new("Marble"), bpy.data.materials.new("Skin")
    objs = seam_grids(bpy, (left_mat, right_mat))
    for mat, preset in ((left_mat, "MARBLE"), (right_mat, "SKIN1")):
        s = mat.translucent
        s.enabled, s.preset, s.profile, s.coefficients = True, preset, "DIPOLE", 16
    assert bpy.ops.translucent.precompute(material_name=left_mat.name) == {"FINISHED"}
    marble = read_preview(objs[0]).copy()
    assert bpy.ops.translucent.precompute(material_name=right_mat.name) == {"FINISHED"}
    np.testing.assert_array_equal(read_preview(objs[0]), marble)
    assert session.SESSIONS[left_mat.name].info.occluders == [objs[1].name]
    assert session.SESSIONS[right_mat.name].info.occluders == [objs[0].name]
    assert read_preview(objs[1]).max() > 0
    sess, m = session.SESSIONS[left_mat.name], left_mat.translucent.material()
    b = sess.transport.radiosity(m)
    co = np.array([objs[0].matrix_world @ v.co for v in objs[0].data.vertices])
    assert assert_own_half_plane(b, co, m, entering(m.eta, 1.0, 3.0)) > 50


def test_two_touching_objects_of_one_material_exchange_no_light_in_one_precompute(addon):
    # Issue 30 point 4: the same grids sharing one material: one precompute for both, and still
    # no light crosses between them (each object its own medium, as in Cycles).
    import bpy

    from addon import session

    wax = bpy.data.materials.new("Marble")
    objs = seam_grids(bpy, (wax, wax))
    s = wax.translucent
    s.enabled, s.preset, s.profile, s.coefficients = True, "MARBLE", "DIPOLE", 16
    assert bpy.ops.translucent.precompute(material_name=wax.name) == {"FINISHED"}
    sess, m = session.SESSIONS[wax.name], wax.translucent.material()
    assert sorted(sess.objects) == sorted(o.name for o in objs) and sess.info.occluders == []
    b = sess.transport.radiosity(m)
    checked = 0
    for obj, r in zip(objs, sess.info.objects):
        assert r.name == obj.name
        co = np.array([obj.matrix_world @ v.co for v in obj.data.vertices])
        checked += assert_own_half_plane(b[r.start:r.start + r.count], co, m, entering(m.eta, 1.0, 3.0))
    assert checked > 100


def test_eyes_of_another_material_in_a_scene_with_a_floor_and_a_box(addon):
    # Suzanne (a concave head: she lights herself) with her two eyes in an opaque material, on a
    # floor, a box beside her, a key light: the add-on passes the eyes' albedo apart from the
    # uniform skin (`others=`), the preview is that call's answer on the skin's vertices, the
    # eyes' vertices and the other objects keep what they held, and a brighter eye colour is read
    # at the next edit on the same transport and sends the skin more of the head's own light.
    import bpy

    from addon import edits, session
    from blender_scripts.lib import scenes

    from helpers import key_light

    skin, eye = bpy.data.materials.new("Skin"), bpy.data.materials.new("Eyes")
    p = skin.node_tree.nodes["Principled BSDF"]
    p.inputs["Subsurface Weight"].default_value = 1.0
    p.inputs["Subsurface Scale"].default_value = 0.01
    p.inputs["Base Color"].default_value = (0.8, 0.5, 0.4, 1.0)
    eye_bsdf = eye.node_tree.nodes["Principled BSDF"]
    eye_bsdf.inputs["Base Color"].default_value = (0.05, 0.05, 0.05, 1.0)
    bpy.ops.mesh.primitive_monkey_add(size=0.2)
    head = bpy.context.active_object
    head.data.materials.append(skin)
    head.data.materials.append(eye)
    # The eyes: the two smallest loose parts of Suzanne's mesh.
    mesh = head.data
    eyes = scenes.smallest_parts(mesh)
    mesh.polygons.foreach_set("material_index", eyes.astype(np.int32))
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(0.0, 0.0, -0.12))
    floor = bpy.context.active_object
    bpy.ops.mesh.primitive_cube_add(size=0.05, location=(0.15, 0.0, -0.09))
    box = bpy.context.active_object
    key_light(bpy, location=(0.1, -0.3, 0.3), energy=20.0)
    s = skin.translucent
    s.enabled = True
    s.source = "PRINCIPLED"
    s.coefficients = 8
    s.method = "PRT"
    hashes = [mesh_hash(o.data) for o in (head, floor, box)]
    assert bpy.ops.translucent.precompute(material_name=skin.name) == {"FINISHED"}
    sess = session.SESSIONS[skin.name]
    assert sess.base_color is None and sess.others is not None and sess.info.occluders
    on_eyes = np.zeros(len(mesh.vertices), bool)
    on_eyes[[v for f in mesh.polygons if eyes[f.index] for v in f.vertices]] = True
    previewed = np.isnan(sess.others[:, 0])  # NaN rows: the skin's vertices
    np.testing.assert_array_equal(previewed, ~on_eyes)  # the eyes are separate parts: no seam
    m = skin.translucent.material()
    shown = read_preview(head)
    np.testing.assert_allclose(shown[previewed], sess.transport.radiance(m, others=sess.others)[previewed],
                               rtol=1e-6)
    transport = sess.transport
    eye_bsdf.inputs["Base Color"].default_value = (0.9, 0.9, 0.9, 1.0)
    bpy.context.view_layer.update()
    edits.follow_principled(bpy.context.scene, bpy.context.evaluated_depsgraph_get())
    assert sess.transport is transport and not sess.edit_message, sess.edit_message
    np.testing.assert_allclose(sess.others[~previewed], 0.9, rtol=1e-6)
    brighter = read_preview(head)
    np.testing.assert_allclose(brighter[previewed], transport.radiance(m, others=sess.others)[previewed], rtol=1e-6)
    gain = brighter[previewed].sum(axis=0) / shown[previewed].sum(axis=0) - 1.0
    assert (gain > 0.005).all(), gain  # 1.3-1.5 % measured
    assert [mesh_hash(o.data) for o in (head, floor, box)] == hashes
    assert [sl.material for sl in head.material_slots] == [skin, eye]
