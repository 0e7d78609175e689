"""Benchmark of the hierarchy (Mertens 2003; issue 10, point 7), like Mertens' Table 3: one shape
at about 2k, 8k, 32k and 131k triangles (the Stanford bunny at 10 cm, clustered down to ~2k
triangles and subdivided 1-3 times), marble, the standard lights (a point light and a sun,
shadows ray cast). For each size: links, links per triangle, and milliseconds per mode, median
of several runs:
- on-the-fly: everything from scratch (irradiance, refinement from the root, gather);
- render: a light moved, the same links (irradiance, pull, gather, push);
- incremental: the mesh deformed (a new BVH and irradiance, links re-checked, gather).
Timings live here, never in tests. Budgets (issue 10): on-the-fly at 131k < 400 ms and render
after a light move < 100 ms on the 2-core machine; growth near n log n.

Run: `make bench` (or .venv/bin/python blender_scripts/bench_hierarchy.py [--runs N] [--profile dipole]).
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from blender_scripts.lib import models  # noqa: E402
from blender_scripts.lib.machine import describe as machine  # noqa: E402

import translucent  # noqa: E402


def cluster_vertices(p: np.ndarray, t: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertex clustering on a grid of `cell` (Rossignac & Borrel): a coarse mesh of the same
    shape. Faces that collapse are dropped."""
    key = np.floor(p / cell).astype(np.int64)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    q = np.zeros((len(counts), 3))
    np.add.at(q, inverse, p)
    q /= counts[:, None]
    f = inverse[t]
    keep = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0])
    f = np.unique(np.sort(f[keep], axis=1), axis=0, return_index=True)[1]
    faces = inverse[t][keep][np.sort(f)]
    used = np.unique(faces)
    remap = np.full(len(q), -1)
    remap[used] = np.arange(len(used))
    return q[used].astype(np.float32), remap[faces].astype(np.int64)


def base_mesh(target: int = 2016) -> tuple[np.ndarray, np.ndarray]:
    p, t = models.load("stanford-bunny.obj", diagonal=0.1)
    lo, hi = 1e-4, 0.05
    best = (p, t)
    for _ in range(30):
        cell = math.sqrt(lo * hi)
        q, f = cluster_vertices(p, t, cell)
        best = (q, f)
        if abs(len(f) - target) < 0.03 * target:
            break
        if len(f) > target:
            lo = cell
        else:
            hi = cell
    return best


CPU = []  # CPU seconds of every timed run (all threads): the work, whatever else shares the cores


def time_it(f, runs: int) -> float:
    """Median wall milliseconds of `runs` calls; their CPU milliseconds go to CPU."""
    times, cpu = [], []
    for _ in range(runs):
        c0, t0 = time.process_time(), time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    CPU.append(1e3 * statistics.median(cpu))
    return 1e3 * statistics.median(times)


def timed(h, run, runs: int) -> tuple[float, float, dict]:
    """`time_it(run, runs)`: median wall and CPU milliseconds, and the report of `h` after them."""
    ms = time_it(run, runs)
    return ms, CPU[-1], dict(h.report)


def light_move(h, lights, material):
    """A run that moves the key light (`h` switches between the two light sets of `lights`,
    each call the other), then evaluates `material`."""
    toggle = list(lights)

    def run():
        h.update(lights=toggle[0])
        toggle.reverse()
        h.radiosity(material)

    return run


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--profile", default="cycles", choices=["cycles", "dipole"])
    ap.add_argument("--receivers", default="faces", choices=["vertices", "faces"],
                    help="where B is gathered: faces (Mertens' scheme, as his Table 3; the budgets "
                         "below are for it) or vertices (the default of translucent.Hierarchy)")
    ap.add_argument("--levels", type=int, default=4, help="sizes: the base and 1..levels-1 subdivisions")
    args = ap.parse_args()
    print(f"machine: {machine()}; load average {os.getloadavg()[0]:.1f} at start; receivers: {args.receivers}")
    print(f"translucent {translucent.__version__}; {args.profile} profile, marble, bunny at 10 cm, "
          f"median of {args.runs} runs; eps = (0.005, 0.5)")
    marble = translucent.Material.preset("marble", mm_per_unit=1000.0)
    p, t = base_mesh()
    rows = []
    for level in range(args.levels):
        if level:
            p, t = models.subdivide(p, t)
        scene = models.standard_scene(p, t)
        moved = models.standard_scene(p, t)
        # The key light moved to the other side (a new irradiance everywhere).
        moved_light = translucent.Scene(p, t)
        diag = float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))
        moved_light.add_point_light((-0.8 * diag, 0.9 * diag, 1.0 * diag), power=110.0 * diag**2)
        moved_light.add_sun(direction=(0.5, 0.6, -0.62), irradiance=2.0)
        del moved

        t0 = time.perf_counter()
        fly = translucent.Hierarchy(scene, marble, profile=args.profile, mode="on_the_fly", receivers=args.receivers)
        first = time.perf_counter() - t0
        build = fly.report["seconds_build"]
        # On the fly a light move is a new irradiance and everything from the root.
        fly_ms, fly_cpu, fly_report = timed(fly, light_move(fly, (moved_light, scene), marble), args.runs)

        render = translucent.Hierarchy(scene, marble, profile=args.profile, mode="render", receivers=args.receivers)
        links = render.report["links"]
        render_ms, render_cpu, render_report = timed(render, light_move(render, (moved_light, scene), marble),
                                                     args.runs)

        inc = translucent.Hierarchy(scene, marble, profile=args.profile, mode="incremental", receivers=args.receivers)
        k = [0]

        def deform():
            k[0] += 1
            # A bend that grows each run: every vertex moves, the topology stays.
            a = 0.02 * k[0] * (p[:, 2:3] / diag)
            q = p + a * np.concatenate([np.zeros_like(a), np.sin(a) * diag, np.zeros_like(a)], axis=1)
            inc.update(positions=q.astype(np.float32))
            inc.radiosity(marble)

        inc_ms, inc_cpu, inc_report = timed(inc, deform, args.runs)
        n = len(t)
        rows.append(dict(n=n, links=links, build=build, first=first, fly=fly_ms, render=render_ms, inc=inc_ms,
                         fly_cpu=fly_cpu, render_cpu=render_cpu, inc_cpu=inc_cpu,
                         fly_report=fly_report, render_report=render_report, inc_report=inc_report))
        print(f"{n} triangles: build {build * 1e3:.0f} ms, on-the-fly {fly_ms:.1f} ms "
              f"(irradiance {1e3 * fly_report['seconds_irradiance']:.1f}, links+gather "
              f"{1e3 * fly_report['seconds_links']:.1f}, estimate {1e3 * fly_report['seconds_estimate']:.1f}; "
              f"{fly_report['links']} links used), render {render_ms:.1f} ms (irradiance "
              f"{1e3 * render_report['seconds_irradiance']:.1f}, gather {1e3 * render_report['seconds_links']:.1f}), "
              f"incremental {inc_ms:.1f} ms (links {1e3 * inc_report['seconds_links']:.1f}); "
              f"estimate {100 * max(fly_report['error_estimate']):.2f} %", flush=True)

    print()
    print("| triangles | links (stored) | links / triangle | on-the-fly ms | incremental ms | render ms | "
          "CPU ms (fly / incr. / render) | on-the-fly CPU ms / (n log2 n) x 1e6 |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        nlogn = r["n"] * math.log2(r["n"])
        print(f"| {r['n']} | {r['links']} | {r['links'] / r['n']:.1f} | {r['fly']:.1f} | {r['inc']:.1f} | "
              f"{r['render']:.1f} | {r['fly_cpu']:.0f} / {r['inc_cpu']:.0f} / {r['render_cpu']:.0f} | "
              f"{1e6 * r['fly_cpu'] / nlogn:.2f} |")
    big = rows[-1]
    print(f"\nbudgets at {big['n']} triangles: on-the-fly {big['fly']:.0f} ms (< 400), "
          f"render after a light move {big['render']:.0f} ms (< 100)")
    print(f"load average {os.getloadavg()[0]:.1f} at the end")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
