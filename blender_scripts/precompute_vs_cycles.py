"""The precompute against Cycles' own vertex bake at equal error (issue 29, point 4), and the
time to the first preview.

For each model (under the demo's light: a point light and a dim world) and material:
- a Cycles vertex bake at `--spp` (1024: the reference) and a ladder of cheaper bakes
  (`--ladder`, another sampling seed), each timed once and compared with the reference;
- PRT's first preview (`Prt(first_preview=True)`, what the add-on shows while the walks run)
  and its full precompute, each timed with the preview's `radiance` (median of `--runs`) and
  compared with the same reference.

The Cycles time at PRT's error is read off the ladder: log time against log error, straight
between the two rungs that bracket it. The ratio is that time over PRT's: how many times
faster PRT reaches the error than Cycles' own bake on the same machine (the issue asks for 5).
Outside the ladder it is stated as a bound. Errors are area-weighted relative RMS over every
vertex, worst channel; each includes the reference's own noise, for Cycles' rungs and PRT
alike. Bakes are cached (out/cache), their times with them.

Run: .venv/bin/python blender_scripts/precompute_vs_cycles.py [--models suzanne stanford-bunny.obj]
     [--materials marble skin1] [--runs 3]
"""

from __future__ import annotations

import argparse
import math
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


def cycles_time_at(error: float, ladder: list[tuple[int, float, float]]) -> tuple[float, str]:
    """Cycles' bake time at `error`, from rungs (spp, seconds, error) in rising spp: log-log
    interpolation between the two rungs that bracket it. Beyond the ladder, the nearest rung's
    time and "<" (PRT's error is above the cheapest rung's) or ">" (below the dearest's)."""
    rungs = sorted(ladder)
    if error >= rungs[0][2]:
        return rungs[0][1], "<"
    for (s0, t0, e0), (s1, t1, e1) in zip(rungs, rungs[1:]):
        if e1 <= error <= e0:
            f = math.log(error / e0) / math.log(e1 / e0) if e1 != e0 else 0.0
            return math.exp(math.log(t0) + f * math.log(t1 / t0)), ""
    return rungs[-1][1], ">"


def timed(make, runs: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(runs):
        t0 = time.perf_counter()
        out = make()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--models", nargs="+", default=["suzanne", "stanford-bunny.obj"])
    ap.add_argument("--materials", nargs="+", default=["marble", "skin1"])
    ap.add_argument("--runs", type=int, default=3, help="PRT runs (median); the full precompute runs once")
    ap.add_argument("--spp", type=int, default=1024, help="the reference bake's samples")
    ap.add_argument("--ladder", type=int, nargs="+", default=[4, 16, 64, 256], help="Cycles' cheaper bakes")
    args = ap.parse_args(argv)
    print(f"machine: {machine()}")
    for model in args.models:
        obj, _ = scenes.build_scene(model)
        scene, _ = export.export_scene([obj])
        bake_obj = scenes.preview_object(obj)
        bake_obj.data.materials.clear()
        w = scene.vertex_areas[:, 0]
        print(f"\n{model}: {scene.vertex_count} vertices under the demo's light; Cycles vertex bakes against "
              f"its {args.spp}-spp bake", flush=True)
        for name in args.materials:
            m = scenes.material(name)

            def first():
                return translucent.Prt(scene, m, first_preview=True, backend="cpu").radiance(m)

            def full():
                return translucent.Prt(scene, m, backend="cpu", single_scattering=False).radiance(m)

            # PRT first, before any bake of this run: Cycles' threads and memory stay behind it
            # (the bunny's full precompute took 40 s after its bakes, 21-23 s alone).
            prt = [(label, *timed(make, runs), runs)
                   for label, make, runs in (("first preview", first, args.runs), ("full precompute", full, 1))]
            ref, ref_s = cr.bake_vertices(bake_obj, m, args.spp)
            ladder = []
            for spp in args.ladder:
                values, seconds = cr.bake_vertices(bake_obj, m, spp, seed=cr.LADDER_SEED)
                ladder.append((spp, seconds, rel(values, ref, w)))
            rungs = ", ".join(f"{spp} spp {s:.1f} s {100 * e:.2f} %" for spp, s, e in ladder)
            print(f"  {name}: Cycles {rungs} (reference {ref_s:.0f} s; bake times from when they were made)",
                  flush=True)
            for label, seconds, b, runs in prt:
                err = rel(b, ref, w)
                t_cycles, bound = cycles_time_at(err, ladder)
                ratio = t_cycles / seconds
                print(f"    PRT {label}: {seconds:.2f} s ({'median of ' + str(runs) if runs > 1 else 'one run'}), "
                      f"{100 * err:.2f} % from the reference; Cycles' bake at that error {bound}{t_cycles:.2f} s: "
                      f"PRT x{bound}{ratio:.1f} [issue 29: x5; the first preview 1 s and 10 %]", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
