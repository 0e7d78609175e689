"""The splatting (Shah 2009, issue 31) against the ground truth, vertex by vertex: the shared
models at 10 cm under the benchmark lighting (a point light and a sun, no world), Jensen's
marble and skimmilk, the dipole and Cycles' profile, eps 0.01 (the paper's); area-weighted
relative RMS per channel over random receiver vertices, and the seconds of both. Issue 31's
bar: under 3 %.

With `--lighting studio` the benchmark lighting gains a square area light (the key's power,
beside the model) and a dim grey world, both peeled (Shah's §Environment Lighting; no light
view holds them).

Run: .venv/bin/python blender_scripts/accuracy_splat.py [--models stanford-bunny.obj horse.ply]
     [--receivers 100] [--eps 0.01] [--max-grid 1024] [--peel-grid 1024] [--lighting studio]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import translucent  # noqa: E402
from blender_scripts.lib import models  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--models", nargs="+", default=["stanford-bunny.obj", "horse.ply"])
    ap.add_argument("--presets", nargs="+", default=["marble", "skimmilk"])
    ap.add_argument("--profiles", nargs="+", default=["dipole", "cycles"])
    ap.add_argument("--receivers", type=int, default=100)
    ap.add_argument("--eps", type=float, default=0.01)
    ap.add_argument("--max-grid", type=int, default=1024)
    ap.add_argument("--rel-tol", type=float, default=1e-3)
    ap.add_argument("--peel-grid", type=int, default=1024)
    ap.add_argument("--lighting", choices=["standard", "studio"], default="standard")
    args = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; eps {args.eps}, "
          f"max grid {args.max_grid}, peel grid {args.peel_grid}, {args.receivers} receivers, "
          f"{args.lighting} lighting")
    print("| model | preset | profile | rel. RMS (R, G, B) % | its estimate % (s) | splats | grid | splat s | "
          "reference s |")
    print("|---|---|---|---|---|---|---|---|---|")
    worst = 0.0
    for model in args.models:
        p, t = models.load(model, diagonal=0.1)
        scene = models.standard_scene(p, t)
        if args.lighting == "studio":
            diag = float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))
            scene.add_area_light((-1.2 * diag, -0.4 * diag, 0.6 * diag), (1.0, 0.33, -0.5), (-0.33, 1.0, 0.0),
                                 0.8 * diag, 0.8 * diag, power=110.0 * diag**2)
            scene.set_world(color=(0.05, 0.05, 0.05))
        rng = np.random.default_rng(7)
        idx = np.sort(rng.choice(scene.vertex_count, size=min(args.receivers, scene.vertex_count), replace=False))
        for preset in args.presets:
            m = translucent.Material.preset(preset, mm_per_unit=1000.0)
            for profile in args.profiles:
                splat = translucent.Splat(scene, profile=profile, eps=args.eps, max_grid=args.max_grid,
                                          peel_grid=args.peel_grid)
                b, ev, report = splat.radiosity(m), splat.last_eval, splat.report
                t0 = time.perf_counter()
                ref = translucent.reference_radiosity(scene, m, rel_tol=args.rel_tol, receivers=idx.tolist(),
                                                      profile=profile)
                ref_s = time.perf_counter() - t0
                err = translucent.relative_error(b[idx], ref, scene.vertex_areas[idx, 0])
                worst = max(worst, max(err["rms"]))
                grids = "/".join(str(x["grid"]) for x in report["lights"])
                if report["peel"] is not None:
                    peel = report["peel"]
                    grids += f" + peel {peel['grid']}x3 ({peel['samples']:,} splats, {peel['layers']} layers)"
                rms = ", ".join(f"{100 * x:.2f}" for x in err["rms"])
                est = ", ".join(f"{100 * x:.2f}" for x in ev["error_estimate"])
                est += f" ({report['estimate']['seconds']:.2f})"
                print(f"| {model} | {preset} | {profile} | {rms} | {est} | {report['splats']:,} | {grids} | "
                      f"{ev['seconds']:.2f} | {ref_s:.1f} |", flush=True)
    print(f"worst channel rel. RMS: {100 * worst:.2f} % (issue 31's bar: under 3 %)")
    return 0 if worst < 0.03 else 1


if __name__ == "__main__":
    raise SystemExit(main())
