"""The first preview against Cycles (issue 29, point 4): the 10 cm bunny under the demo's light,
the first preview the add-on shows while the walks run (`Prt(first_preview=True)`: no walks, at
most 150,000 samples, the own light on 16 rays a vertex) and the full precompute, each timed
(median of `--runs`) and compared with a 1024-spp Cycles vertex bake of the same scene
(area-weighted relative RMS over every vertex, worst channel). Bakes are cached (out/cache).

Run: .venv/bin/python blender_scripts/first_preview_vs_cycles.py [--materials marble skin1] [--runs 3]
"""

from __future__ import annotations

import argparse
import pathlib
import statistics
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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--materials", nargs="+", default=["marble", "skin1"])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--spp", type=int, default=1024)
    args = ap.parse_args(argv)
    print(f"machine: {machine()}")
    obj, _ = scenes.build_scene("stanford-bunny.obj")
    scene, _ = export.export_scene([obj])
    bake_obj = scenes.preview_object(obj)
    bake_obj.data.materials.clear()
    w = scene.vertex_areas[:, 0]
    print(f"the bunny at 10 cm, {scene.vertex_count} vertices, the demo's light; Cycles vertex bakes at {args.spp} spp")
    for name in args.materials:
        m = scenes.material(name)
        bake, bake_s = cr.bake_vertices(bake_obj, m, args.spp)
        firsts = []
        for _ in range(args.runs):
            t0 = time.perf_counter()
            first = translucent.Prt(scene, m, first_preview=True, backend="cpu")
            b_first = first.radiance(m)
            firsts.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        full = translucent.Prt(scene, m, backend="cpu", single_scattering=False)
        b_full = full.radiance(m)
        full_s = time.perf_counter() - t0
        print(f"{name}: first preview {statistics.median(firsts):.2f} s (median of {args.runs}), "
              f"{100 * rel(b_first, bake, w):.2f} % from the bake; the full precompute {full_s:.1f} s, "
              f"{100 * rel(b_full, bake, w):.2f} % from it; first vs full {100 * rel(b_first, b_full, w):.2f} % "
              f"(bake {bake_s:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
