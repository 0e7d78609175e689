"""A pose against Cycles (issue 29, point 3): the demo's Suzanne (Subdivision 2) with an
armature bending her left ear by 40 degrees, previewed three ways after the pose and each
compared with a Cycles vertex bake of the posed mesh:

- the hierarchy updated in place (`Hierarchy.update(positions=...)`): the half-space profile
  alone (what Auto picked for a deformation before the pose update), and with walks
  (`Hierarchy(walks=True)`: the walks and the own light carried to the pose, then
  `retrace_walks` walking the pose);
- PRT updated to the pose (`Prt.update(lights=posed scene)`: samples, irradiance and transport on
  the posed mesh, the walks and the object's own light carried from the rest pose), on a first
  preview's samples (the default) and on the precompute's (`first_preview=False`);
- a fresh PRT precompute on the posed mesh (the walks traced on it: the refinement).

For each material it prints the seconds of each and its area-weighted relative RMS against the
bake (worst channel), over every vertex and over the ear's vertices. Bakes are cached
(out/cache/cycles).

Run: .venv/bin/python blender_scripts/pose_vs_cycles.py [--materials marble skin1] [--angle 40]
"""

from __future__ import annotations

import argparse
import math
import pathlib
import sys
import time

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import translucent  # noqa: E402
from addon import export  # noqa: E402
from blender_scripts.lib import cycles_reference as cr  # noqa: E402
from blender_scripts.lib import scenes  # noqa: E402
from blender_scripts.lib.machine import describe as machine  # noqa: E402
from blender_scripts.lib.metrics import rel  # noqa: E402


def rig_left_ear(obj: bpy.types.Object) -> bpy.types.PoseBone:
    """An armature whose one bone holds Suzanne's left ear (+X, the outer third of her width,
    weights ramping from 0 to 1 over its base): the pose bone. The Armature modifier goes before
    the Subdivision, as a rigged character has it."""
    xs = np.array([v.co.x for v in obj.data.vertices])
    x0, x1 = 0.55 * xs.max(), 0.7 * xs.max()
    ear = [v for v in obj.data.vertices if v.co.x > x0]
    centre = np.mean([tuple(v.co) for v in ear if v.co.x < x1], axis=0)
    arm = bpy.data.armatures.new("Rig")
    rig = bpy.data.objects.new("Rig", arm)
    bpy.context.scene.collection.objects.link(rig)
    bpy.context.view_layer.objects.active = rig
    bpy.ops.object.mode_set(mode="EDIT")
    bone = arm.edit_bones.new("Ear")
    bone.head = (x0, centre[1], centre[2])
    bone.tail = (xs.max(), centre[1], centre[2])
    bpy.ops.object.mode_set(mode="OBJECT")
    group = obj.vertex_groups.new(name="Ear")
    for v in ear:
        group.add([v.index], float(min(1.0, (v.co.x - x0) / (x1 - x0))), "REPLACE")
    mod = obj.modifiers.new("Armature", "ARMATURE")
    mod.object = rig
    obj.modifiers.move(len(obj.modifiers) - 1, 0)
    bpy.context.view_layer.objects.active = obj
    return rig.pose.bones["Ear"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--materials", nargs="+", default=["marble", "skin1"])
    ap.add_argument("--angle", type=float, default=40.0, help="the ear's bend [degrees]")
    ap.add_argument("--spp", type=int, default=1024)
    args = ap.parse_args(argv)
    print(f"machine: {machine()}")
    obj, _ = scenes.build_scene("suzanne")
    bone = rig_left_ear(obj)
    bpy.context.view_layer.update()
    rest, _ = export.export_scene([obj])
    bone.rotation_mode = "XYZ"
    bone.rotation_euler = (0.0, 0.0, math.radians(args.angle))  # about the bone's Z: the ear swings back
    bpy.context.view_layer.update()
    posed, _ = export.export_scene([obj])
    moved = np.linalg.norm(posed.positions - rest.positions, axis=1)
    ear = moved > 1e-4
    bake_obj = scenes.preview_object(obj)
    bake_obj.data.materials.clear()
    w = posed.vertex_areas[:, 0]
    print(f"Suzanne (Subdivision 2), {posed.vertex_count} vertices; the left ear bent {args.angle:.0f} degrees: "
          f"{int(ear.sum())} vertices moved, up to {1000 * moved.max():.1f} mm; Cycles vertex bakes at {args.spp} spp")

    def errors(b, bake):
        return f"{100 * rel(b, bake, w):.2f} % (ear {100 * rel(b[ear], bake[ear], w[ear]):.2f} %)"

    for name in args.materials:
        m = scenes.material(name)
        bake, bake_s = cr.bake_vertices(bake_obj, m, args.spp)
        h = translucent.Hierarchy(rest, m, mode="render", world_shadows=True)
        h.radiance(m)
        t0 = time.perf_counter()
        h.update(positions=posed.positions, normals=posed.normals)
        hb = h.radiance(m)
        h_s = time.perf_counter() - t0
        hw = translucent.Hierarchy(rest, m, mode="render", world_shadows=True, walks=True)
        t0 = time.perf_counter()
        hw.update(positions=posed.positions, normals=posed.normals)
        hwb = hw.radiance(m)
        hw_s = time.perf_counter() - t0
        hw.retrace_walks()
        t0 = time.perf_counter()
        hrb = hw.radiance(m)
        hr_s = time.perf_counter() - t0
        rest_prt = translucent.Prt(rest, m, backend="cpu", single_scattering=False)
        carried = {}
        for quick in (True, False):
            prt = translucent.Prt(rest, m, backend="cpu", single_scattering=False)
            t0 = time.perf_counter()
            r = prt.update(lights=posed, first_preview=quick)
            carried[quick] = (prt.radiance(m), time.perf_counter() - t0, r)
        t0 = time.perf_counter()
        fresh = translucent.Prt(posed, m, backend="cpu", single_scattering=False)
        fb = fresh.radiance(m)
        f_s = time.perf_counter() - t0
        still = rest_prt.radiance(m)
        (qb, q_s, qr), (pb, p_s, pr) = carried[True], carried[False]
        print(f"{name}: hierarchy update {h_s:.2f} s, {errors(hb, bake)}; with walks carried {hw_s:.2f} s, "
              f"{errors(hwb, bake)}, retraced {hr_s:.2f} s more, {errors(hrb, bake)}; PRT pose update (first preview's "
              f"samples) {q_s:.2f} s, {errors(qb, bake)}; PRT pose update (precompute's samples) {p_s:.2f} s, "
              f"{errors(pb, bake)} ({qr['walks_traced'] + pr['walks_traced']} walks traced); fresh PRT on the "
              f"pose {f_s:.2f} s, {errors(fb, bake)}; the rest pose's preview left as it was "
              f"{errors(still, bake)} (bake {bake_s:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
