"""Issue 12: light that tunnels. A walk that leaves through a surface inside another part of
the same mesh (an eyeball sunk into a head) goes on, in Cycles, past that part after the exit's
bounce: Cycles files that light as indirect. `reference_radiance(..., tunnel=False)` leaves it
out and so matches a bake of Cycles' direct light at the rim of a sunk ball too. Measured on
Suzanne in ketchup at three receivers by the eye sockets (red): the direct-light bake 0.055,
0.084, 0.055; the reference with the tunnel 0.075, 0.122, 0.089, without it 0.053, 0.083,
0.052."""

import pathlib
import sys

import numpy as np
import pytest

pytestmark = pytest.mark.bpy
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "blender_scripts"))


def test_without_the_tunnel_the_walks_are_cycles_direct_light_by_a_sunk_ball(empty_blend, tmp_path, monkeypatch):
    bpy = empty_blend
    import bmesh
    import cycles_reference as cr

    import translucent
    from addon import export

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
