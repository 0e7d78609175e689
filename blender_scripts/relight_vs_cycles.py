"""`Prt.update(lights=...)` against Cycles (issue 29): the demo's Suzanne precomputed under one
light, relit to the other (the key light in front, then behind the head, and back), and the
relit preview compared with a Cycles vertex bake of the scene as it is after the move, beside a
fresh precompute under the new light.

For each direction and material it prints: the update's seconds and rays, the relit preview
against the bake and against the fresh precompute, the fresh precompute against the bake, and
each one's own error estimate (area-weighted relative RMS over every vertex, worst channel).
Bakes are cached (out/cache/cycles), so a second run only recomputes PRT.

Run: .venv/bin/python blender_scripts/relight_vs_cycles.py [--materials marble skin1] [--spp 1024]
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import bpy  # noqa: E402,F401

import translucent  # noqa: E402
from addon import export  # noqa: E402
from blender_scripts.lib import cycles_reference as cr  # noqa: E402
from blender_scripts.lib import scenes  # noqa: E402
from blender_scripts.lib.machine import describe as machine  # noqa: E402
from blender_scripts.lib.metrics import rel  # noqa: E402

FRONT = (0.12, -0.22, 0.2)  # the demo's key light (scenes.demo_scene)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--materials", nargs="+", default=["marble", "skin1"])
    ap.add_argument("--spp", type=int, default=1024)
    args = ap.parse_args(argv)
    print(f"machine: {machine()}")
    obj, _ = scenes.build_scene("suzanne")
    key = bpy.data.objects["Key"]
    bake_obj = scenes.preview_object(obj)
    bake_obj.data.materials.clear()
    lit = {}
    for where, location in (("front", FRONT), ("behind", scenes.BACKLIGHT)):
        key.location = location
        bpy.context.view_layer.update()
        lit[where] = export.export_scene([obj])[0]
    w = lit["front"].vertex_areas[:, 0]
    print(f"Suzanne (Subdivision 2), {lit['front'].vertex_count} vertices, key light in front and behind; "
          f"Cycles vertex bakes at {args.spp} spp")
    for name in args.materials:
        m = scenes.material(name)
        for start, end in (("front", "behind"), ("behind", "front")):
            key.location = FRONT if end == "front" else scenes.BACKLIGHT
            bpy.context.view_layer.update()
            bake, bake_s = cr.bake_vertices(bake_obj, m, args.spp)
            prt = translucent.Prt(lit[start], m, backend="cpu", single_scattering=False)
            t0 = time.perf_counter()
            r = prt.update(lights=lit[end])
            wall = time.perf_counter() - t0
            relit = prt.radiance(m)
            relit_est = 100 * max(prt.last_eval["error_estimate"])
            t0 = time.perf_counter()
            fresh_prt = translucent.Prt(lit[end], m, backend="cpu", single_scattering=False)
            fresh_s = time.perf_counter() - t0
            fresh = fresh_prt.radiance(m)
            fresh_est = 100 * max(fresh_prt.last_eval["error_estimate"])
            print(f"{name}, light {start} -> {end}: update {r['seconds']:.2f} s ({wall:.2f} s wall, "
                  f"{r['rays'] / 1e6:.2f} M rays, {r['walks_traced']} walks traced) against a fresh "
                  f"precompute {fresh_s:.2f} s; relit vs Cycles {100 * rel(relit, bake, w):.2f} %, "
                  f"fresh vs Cycles {100 * rel(fresh, bake, w):.2f} %, relit vs fresh "
                  f"{100 * rel(relit, fresh, w):.2f} % (estimates: relit {relit_est:.2f} %, fresh "
                  f"{fresh_est:.2f} %; bake {bake_s:.0f} s)", flush=True)
            # A drag goes on: the key light moved on again, the world as it was. Its irradiance
            # is kept source by source, so only the moved light casts rays.
            key.location = tuple(0.5 * (a + b) for a, b in zip(FRONT, scenes.BACKLIGHT))
            bpy.context.view_layer.update()
            again = prt.update(lights=export.export_scene([obj])[0])
            print(f"  then the key light moved on, the world unchanged: update {again['seconds']:.2f} s, "
                  f"{again['rays'] / 1e6:.2f} M rays (irradiance {again['seconds_irradiance']:.2f} s, "
                  f"transport {again['seconds_transport']:.2f} s)", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
