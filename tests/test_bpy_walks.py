"""Issue 12: the walks through the mesh against a Cycles bake of real geometry. A 5 mm skin
sphere under a sun carries light round to its dark side, which Cycles' walk renders and a
half-space profile cannot see; `reference_radiance` traces the same walk without Blender.
Measured (1024-spp bakes, 4096 walks per vertex): 3.45 % with Cycles' noise 2.0 % and the
walks' 1.35 % (2.4 % beyond both); the half-space profile 25.6 %."""

import numpy as np
import pytest

pytestmark = pytest.mark.bpy


def test_walks_through_a_small_sphere_match_a_cycles_bake(empty_blend, tmp_path, monkeypatch):
    bpy = empty_blend
    import translucent
    from addon import export
    from blender_scripts.lib import cycles_reference as cr

    monkeypatch.setattr(cr, "CACHE", tmp_path)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.005, segments=24, ring_count=12)
    bpy.ops.object.shade_smooth()
    obj = bpy.context.active_object
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = 3.0
    sun.data.angle = 0.0
    sun.rotation_euler = (0.6, 0.3, 0.0)
    bpy.context.scene.collection.objects.link(sun)
    scene, _ = export.export_scene([obj])
    m = translucent.Material.preset("skin1", mm_per_unit=1000.0)
    w = scene.vertex_areas[:, 0]

    # Cycles' direct light (the walks' reference is direct light too), two seeds for its noise.
    bake, _ = cr.bake_vertices(obj, m, 1024, direct_only=True)
    bake2, _ = cr.bake_vertices(obj, m, 1024, direct_only=True, seed=1)
    noise = max(translucent.relative_error(bake, bake2, w)["rms"]) / np.sqrt(2)
    walks, info = translucent.reference_radiance(scene, m, walks=4096, details=True)
    err = max(translucent.relative_error(walks, bake, w)["rms"])
    # The half-space profile's answer for the same sphere (its ground truth through PRT).
    prt = translucent.Prt(scene, m, backend="cpu", interreflection=False, walks=0)
    half = prt.radiosity(m) * translucent.layer_weight(m.roughness, 1.0, m.eta) / np.pi
    err_half = max(translucent.relative_error(half, bake, w)["rms"])
    print(f"walks vs Cycles {100 * err:.2f} % (Cycles noise {100 * noise:.2f} %, walks' noise "
          f"{100 * max(info['noise']):.2f} %); half-space vs Cycles {100 * err_half:.1f} %")
    # Within 2 % beyond the two noises, and far closer than the half-space profile.
    assert err <= 0.02 + 2 * np.hypot(noise, max(info["noise"])), (err, noise, info["noise"])
    assert err_half > 2 * err, (err_half, err)


def test_at_an_open_edge_the_reference_samples_where_the_bake_does(empty_blend, tmp_path, monkeypatch):
    """Blender bakes a vertex as the mean over its corners of Cycles' answer 0.1 mm into each
    corner triangle (`bake_points`); at an open sheet's edge the radiance changes within that
    distance. Mean over the edges of a 10 cm sheet of 21 x 21 vertices under a sun (aniso08,
    1024 spp): bake 0.179 / 0.132 / 0.106; the walk reference entering at the bake points
    0.178 / 0.132 / 0.104 (within 1.6 %), entering at the vertex 0.164 / 0.104 / 0.071 (blue
    33 % low)."""
    import translucent
    from addon import export
    from blender_scripts.lib import cycles_reference as cr
    from blender_scripts.lib import scenes

    monkeypatch.setattr(cr, "CACHE", tmp_path)
    n = 21
    obj = scenes.sheet(n, scenes.SHEET_SIZE, 0.0)
    scene, _ = export.export_scene([obj])
    m = scenes.material("aniso08")
    i, j = np.divmod(np.arange(n * n), n)
    # The edges' vertices less the four corners.
    edge = np.flatnonzero(((i == 0) | (i == n - 1) | (j == 0) | (j == n - 1))
                          & ~(((i == 0) | (i == n - 1)) & ((j == 0) | (j == n - 1))))
    bake, _ = cr.bake_vertices(obj, m, 1024)
    at_bake = translucent.reference_radiance(scene, m, walks=1024, receivers=edge.tolist())
    at_vertex = translucent.reference_radiance(scene, m, walks=1024, receivers=edge.tolist(), at="vertex")
    want = bake[edge].mean(0)
    got, vertex = at_bake.mean(0), at_vertex.mean(0)
    print(f"edge: bake {want}, reference at the bake points {got}, at the vertex {vertex}")
    np.testing.assert_allclose(got, want, rtol=0.04)
    assert vertex[2] < 0.8 * want[2], (vertex, want)
    with pytest.raises(ValueError, match="at must be"):
        translucent.reference_radiance(scene, m, walks=8, receivers=[0], at="corner")


def _sun_from(bpy, rotation):
    """A sun at `rotation` (Euler, radians) and a black world."""
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy, sun.data.angle = 3.0, 0.0
    sun.rotation_euler = rotation
    bpy.context.scene.collection.objects.link(sun)
    world = bpy.data.worlds.new("black")
    bpy.context.scene.world = world
    if world.node_tree is None:  # Blender < 5.0
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0


def test_the_objects_own_light_is_cycles_indirect_light(empty_blend, tmp_path, monkeypatch):
    """The object's own light against Cycles' indirect light (the bake with and without it).
    A 6 cm torus (a Principled material, radius 52 / 12 / 8 mm) under a sun: the inside of the
    ring lights itself; Cycles adds 2.2 / 3.3 / 5.4 % of the direct light. The lit surface
    sends on its lobes' B and what its specular layer reflects (E_spec E): 2.0 / 3.2 / 5.6 %;
    the lobes alone gave 1.8 / 2.9 / 5.2 % (red and green 20 % and 12 % short). And a 2 mm skin1
    wall lit from behind lights a cube in its shadow through its glowing back, in Cycles too:
    0.22 / 0.069 / 0.013 there against the wall back's 0.51 / 0.28 / 0.10 (ours 0.25 / 0.082 /
    0.018 and 0.52 / 0.28 / 0.10; a diffuse surface at the wall's back, lit by nothing
    directly, would send nothing). The bakes take 256 samples: at 1024 the torus's shares were
    the same to 3 % (2.20 / 3.26 / 5.42 % against 2.17-2.26 / 3.20-3.24 / 5.38-5.47 % over two
    seeds) and the wall's means to 0.5 %, in a quarter of the time."""
    import math

    bpy = empty_blend
    import translucent
    from addon import export
    from blender_scripts.lib import cycles_reference as cr
    from blender_scripts.lib import scenes

    monkeypatch.setattr(cr, "CACHE", tmp_path)
    bpy.ops.mesh.primitive_torus_add(major_radius=0.03, minor_radius=0.01, major_segments=48, minor_segments=24)
    bpy.ops.object.shade_smooth()
    torus = bpy.context.active_object
    _sun_from(bpy, (0.7, 0.2, 0.0))
    scene, _ = export.export_scene([torus])
    w = scene.vertex_areas[:, 0]
    m = translucent.Material.from_principled(base_color=(0.29, 0.6, 0.9), radius=(1.0, 0.23, 0.16), scale=0.052,
                                             roughness=0.5, subsurface_weight=1.0, ior=1.3)
    full, _ = cr.bake_vertices(torus, m, 256)
    direct, _ = cr.bake_vertices(torus, m, 256, direct_only=True)
    cycles = (w @ (full - direct)) / (w @ direct)
    prt = translucent.Prt(scene, m, backend="cpu")
    b_on, b_off = prt.radiosity(m), prt.radiosity(m, interreflection=False)
    ours = (w @ (b_on - b_off)) / (w @ b_off)
    print(f"torus: indirect / direct, Cycles {cycles}, ours {ours}")
    assert np.all(cycles > 0.015), cycles
    np.testing.assert_allclose(ours, cycles, rtol=0.1)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    thick = 0.002
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    wall = bpy.context.active_object
    wall.scale = (thick, 0.06, 0.06)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.02, 0.0, 0.0))
    cube = bpy.context.active_object
    cube.scale = (0.02, 0.02, 0.02)
    for o in (wall, cube):
        o.select_set(True)
    bpy.context.view_layer.objects.active = wall
    bpy.ops.object.transform_apply(scale=True)
    bpy.ops.object.join()
    obj = bpy.context.active_object
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.subdivide(number_cuts=12)
    bpy.ops.object.mode_set(mode="OBJECT")
    _sun_from(bpy, (0.0, -math.pi / 2, 0.0))  # travelling along +x: the cube lies in the wall's shadow
    p = np.array([v.co[:] for v in obj.data.vertices])
    centre = (np.abs(p[:, 1]) < 0.008) & (np.abs(p[:, 2]) < 0.008)
    back = centre & (np.abs(p[:, 0] - thick / 2) < 1e-6)
    facing = centre & (np.abs(p[:, 0] - 0.01) < 1e-6)  # the cube's face towards the wall
    m = scenes.material("skin1")
    bake, _ = cr.bake_vertices(obj, m, 256)
    scene, _ = export.export_scene([obj])
    assert scene.irradiance()[facing].max() == 0.0  # in the wall's shadow
    prt = translucent.Prt(scene, m, backend="cpu")
    got = prt.radiance(m)
    print(f"wall's back: Cycles {bake[back].mean(0)}, ours {got[back].mean(0)}; the cube facing it: "
          f"Cycles {bake[facing].mean(0)}, ours {got[facing].mean(0)}")
    np.testing.assert_allclose(got[back].mean(0), bake[back].mean(0), rtol=0.05)
    ratio = got[facing].mean(0) / bake[facing].mean(0)
    assert np.all(bake[facing].mean(0) > 0.1 * bake[back].mean(0))
    assert np.all((ratio > 0.8) & (ratio < 1.4)), ratio
    assert math.isfinite(prt.report["interreflection_share"])


def test_without_the_tunnel_the_walks_are_cycles_direct_light_by_a_sunk_ball(empty_blend, tmp_path, monkeypatch):
    """Issue 12: light that tunnels. A walk that leaves through a surface inside another part of
    the same mesh (an eyeball sunk into a head) goes on, in Cycles, past that part after the exit's
    bounce: Cycles files that light as indirect. `reference_radiance(..., tunnel=False)` leaves it
    out and so matches a bake of Cycles' direct light at the rim of a sunk ball too. Measured on
    Suzanne in ketchup at three receivers by the eye sockets (red): the direct-light bake 0.055,
    0.084, 0.055; the reference with the tunnel 0.075, 0.122, 0.089, without it 0.053, 0.083,
    0.052."""
    bpy = empty_blend
    import bmesh

    import translucent
    from addon import export
    from blender_scripts.lib import cycles_reference as cr

    monkeypatch.setattr(cr, "CACHE", tmp_path)
    # A 6 mm ball with a 2.5 mm ball half sunk into its top: one mesh, two shells.
    mesh = bpy.data.meshes.new("head")
    bm = bmesh.new()
    bmesh.ops.create_icosphere(bm, subdivisions=4, radius=0.006)
    small = bmesh.ops.create_icosphere(bm, subdivisions=3, radius=0.0025)
    bmesh.ops.translate(bm, verts=small["verts"], vec=(0.0, 0.0, 0.006))
    bm.to_mesh(mesh)
    bm.free()
    mesh.shade_smooth()
    obj = bpy.data.objects.new("head", mesh)
    bpy.context.scene.collection.objects.link(obj)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy, sun.data.angle = 3.0, 0.0
    sun.rotation_euler = (0.5, 0.2, 0.0)
    bpy.context.scene.collection.objects.link(sun)
    scene, _ = export.export_scene([obj])
    m = translucent.Material.preset("ketchup", mm_per_unit=1000.0)
    co = np.array([v.co[:] for v in mesh.vertices])
    # The big ball's vertices around the small one's rim, outside it.
    d = np.linalg.norm(co - (0.0, 0.0, 0.006), axis=1)
    rim = np.nonzero((d > 0.0026) & (d < 0.004) & (np.linalg.norm(co, axis=1) > 0.0059))[0]
    assert len(rim) >= 20
    bakes = [cr.bake_vertices(obj, m, 1024, direct_only=True, seed=s, adaptive=False)[0][rim] for s in range(2)]
    bake = np.mean(bakes, 0)
    w = np.ones(len(rim))
    noise = np.array(translucent.relative_error(bakes[0], bakes[1], w)["rms"]) / 2  # of the mean of two
    on = translucent.reference_radiance(scene, m, walks=8192, receivers=rim.tolist())
    off, info = translucent.reference_radiance(scene, m, walks=8192, receivers=rim.tolist(), tunnel=False,
                                               details=True)
    err_on = np.array(translucent.relative_error(on, bake, w)["rms"])
    err_off = np.array(translucent.relative_error(off, bake, w)["rms"])
    print(f"red: bake {bake[:, 0].mean():.4f}, tunnel on {on[:, 0].mean():.4f}, off {off[:, 0].mean():.4f}; "
          f"rel. RMS on {100 * err_on} %, off {100 * err_off} %, bake noise {100 * noise} %")
    assert np.all(err_off <= 0.03 + 3 * np.hypot(noise, info["noise"])), (err_off, noise, info["noise"])
    # The tunnel's light is there in red, the channel that travels: the walks with it are brighter.
    assert on[:, 0].mean() > 1.05 * off[:, 0].mean(), (on[:, 0].mean(), off[:, 0].mean())
    assert err_on[0] > 2 * err_off[0], (err_on, err_off)
