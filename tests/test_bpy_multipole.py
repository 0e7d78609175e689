"""The multipole profile in the add-on (issue 31 point 2), in headless Blender on a scene of two
objects: a sun-lit grid in a material previewed with Profile "Multipole" and a cube elsewhere in
another material (an occluder that shadows none of the grid's middle). Expected values: the pole
sums' closed totals (helpers.slab_totals, helpers.layered_total), written apart from the code."""

import math

import numpy as np
import pytest

from helpers import entering, layered_total, mesh_hash, slab_totals, boundary_a

pytestmark = pytest.mark.bpy


def scene(bpy):
    """A 20 cm grid (81 x 81 vertices, 2.5 mm apart) under a sun straight down (3 W/m^2) in the
    marble "Wax", and a 5 cm cube 30 cm to its side in "Paint"."""
    wax, paint = bpy.data.materials.new("Wax"), bpy.data.materials.new("Paint")
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=80, y_subdivisions=80, size=0.2)
    grid = bpy.context.active_object
    grid.data.materials.append(wax)
    bpy.ops.mesh.primitive_cube_add(size=0.05, location=(0.3, 0.0, 0.1))
    cube = bpy.context.active_object
    cube.data.materials.append(paint)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = 3.0
    bpy.context.scene.collection.objects.link(sun)
    s = wax.translucent
    s.enabled, s.source, s.preset, s.profile, s.coefficients = True, "CUSTOM", "MARBLE", "MULTIPOLE", 16
    s.thickness_mm = 4.0
    return wax, grid, cube


def centre(obj) -> int:
    co = np.array([v.co for v in obj.data.vertices])
    return int(np.argmin(np.linalg.norm(co, axis=1)))


def test_a_slab_and_a_layer_over_it_show_their_closed_forms(addon):
    import bpy

    from addon import session
    from helpers import read_preview

    wax, grid, cube = scene(bpy)
    user_mesh = mesh_hash(grid.data)
    assert bpy.ops.translucent.precompute(material_name=wax.name) == {"FINISHED"}
    sess = session.SESSIONS[wax.name]
    assert sess.profile == "multipole" and sess.info.occluders == [cube.name]
    m = wax.translucent.material()
    assert m.thickness == pytest.approx(0.004)  # 4 mm in Blender's metres
    v = centre(grid)
    a = boundary_a(m.eta)[0]
    e_in = entering(m.eta, 1.0, 3.0)
    sp = [(1 - m.g) * s for s in m.sigma_s]
    slab = e_in * np.array([slab_totals(m.sigma_a[c], sp[c], m.thickness, a, a)[0] for c in range(3)])
    b = sess.transport.radiosity(m)
    np.testing.assert_allclose(b[v], slab, rtol=0.015)
    shown = read_preview(grid)[v].copy()
    np.testing.assert_allclose(shown, sess.transport.radiance(m)[v], rtol=1e-6)  # what the viewport shows

    # A 1.5 mm layer of skin over a half-space of marble: an edit, no new precompute.
    s = wax.translucent
    s.thickness_mm, s.top_layer, s.top_thickness_mm = 0.0, "SKIN1", 1.5
    assert session.SESSIONS[wax.name] is sess and sess.edit_message == ""
    m = wax.translucent.material()
    top = m.top_layer
    expect = e_in * np.array([
        layered_total((top[0][c], (1 - m.g) * top[1][c], top[2]), (m.sigma_a[c], sp[c], math.inf), m.eta)
        for c in range(3)])
    np.testing.assert_allclose(sess.transport.radiosity(m)[v], expect, rtol=0.015)
    assert not np.allclose(read_preview(grid)[v], shown, rtol=0.05)  # the viewport followed

    # Thinner than its source depth: the edit is not shown and the panel says why.
    s.top_thickness_mm = 0.05
    assert sess.edit_message.startswith("not shown:") and "source depth" in sess.edit_message, sess.edit_message
    assert mesh_hash(grid.data) == user_mesh
