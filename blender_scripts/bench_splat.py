"""Benchmark of the splatting's camera image (Shah 2009; issue 31): `Splat.render` at 800 x 600
of the shared bunny and horse at 10 cm, marble and skimmilk, Cycles' profile, the standard
lights, eps 0.01 and the default 1024 light grid; per pass (the lights' views, the camera's
view, the splats gathered at the pixels, the point mass) and in all, median of several runs.
Then the bunny against the bunny subdivided once (4x the triangles): Shah's Fig. 9 finds the
frame time nearly independent of the triangle count. Timings live here, never in tests.

Each row runs on the CPU (ray casts and the gather on rayon) and again with pass 3 drawn on wgpu
(`Splat.set_backend("gpu")`) on this machine's adapter (printed). On a hardware GPU every case
gets a GPU row; on Mesa's software lavapipe (no GPU) only the bunny in marble and its subdivided
twin do, since each lavapipe frame takes about 40 s (`--all-gpu` draws every case there too).
Passes 1, 2 and 4 are on the CPU either way. The frame includes the error estimate (the ground
truth at 16 vertices), shown in its own column. Run: `make bench` (or .venv/bin/python
blender_scripts/bench_splat.py [--runs N] [--size W H] [--backends cpu gpu] [--presets marble]
[--all-gpu] [--models horse.ply]).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from blender_scripts.lib import models  # noqa: E402
from blender_scripts.lib.machine import describe as machine  # noqa: E402

import translucent  # noqa: E402

PASSES = (("seconds_light_view", "light views"), ("seconds_camera_view", "camera view"),
          ("seconds_splat", "splats gathered"), ("seconds_point_mass", "point mass"),
          ("seconds_estimate", "error estimate"))


def camera(p: np.ndarray) -> dict:
    """A view that frames the model (its diagonal about two thirds of the image's height)."""
    c = 0.5 * (p.min(axis=0) + p.max(axis=0))
    diag = float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))
    d = np.array([0.3, 0.35, 0.9])
    return dict(eye=tuple(c + 1.8 * diag * d / np.linalg.norm(d)), target=tuple(c), up=(0.0, 1.0, 0.0))


def save_png(image: np.ndarray, path: str) -> None:
    """The radiance display-encoded as the viewport draws it (clamped, gamma 1/2.2)."""
    import matplotlib.pyplot as plt

    plt.imsave(path, np.clip(image, 0.0, 1.0) ** (1.0 / 2.2))


def bench(p, t, preset: str, size, runs: int, backend: str, png: str | None = None) -> tuple[dict, int, int]:
    scene = models.standard_scene(p, t)
    m = translucent.Material.preset(preset, mm_per_unit=1000.0)
    splat = translucent.Splat(scene, profile="cycles", backend="cpu")
    if backend == "gpu":
        splat.set_backend("gpu")
    view = camera(p)
    times: dict[str, list[float]] = {k: [] for k, _ in PASSES}
    times["total"], times["draw"] = [], []
    for _ in range(runs):
        image, _mask = splat.render(m, size=size, **view)
        r = splat.report
        r = {**r, "seconds_estimate": r["estimate"]["seconds"] if r["estimate"] else 0.0}
        for k, _ in PASSES:
            times[k].append(r[k])
        times["total"].append(splat.last_eval["seconds"])
        times["draw"].append(r["gpu"]["seconds_draw"] if r["gpu"] else float("nan"))
    if png:
        save_png(image, png)
    return {k: statistics.median(v) for k, v in times.items()}, splat.report["splats"], splat.report["pixels"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--size", type=int, nargs=2, default=(800, 600))
    ap.add_argument("--models", nargs="+", default=["stanford-bunny.obj", "horse.ply"])
    ap.add_argument("--png", help="save the first model's marble image here")
    ap.add_argument("--backends", nargs="+", default=["cpu", "gpu"], choices=["cpu", "gpu"])
    ap.add_argument("--presets", nargs="+", default=["marble", "skimmilk"])
    ap.add_argument("--all-gpu", action="store_true", help="on a software adapter too, every case")
    args = ap.parse_args()
    size = tuple(args.size)
    backends, software = list(args.backends), False
    if "gpu" in backends:
        try:
            words = translucent.Splat(models.standard_scene(*models.load(args.models[0], diagonal=0.1)),
                                      backend="cpu").set_backend("gpu")
        except RuntimeError as e:
            print(f"no GPU row: {e}")
            backends.remove("gpu")
        else:
            print(f"pass 3 on the GPU: {words}")
            software = "(Cpu," in words
    print(f"machine: {machine()}; {size[0]} x {size[1]}, eps 0.01, light grid 1024, median of {args.runs}")
    print("| model | triangles | preset | pass 3 on | splats | pixels | " + " | ".join(n for _, n in PASSES)
          + " | of which GPU draw | frame s |")
    print("|---|---|---|---|---|---|" + "---|" * len(PASSES) + "---|---|")
    for name in args.models:
        p, t = models.load(name, diagonal=0.1)
        meshes = [(name, p, t)]
        if name == args.models[0]:
            meshes.append((f"{name} subdivided", *models.subdivide(p, t)))
        for label, q, u in meshes:
            for preset in args.presets:
                if label.endswith("subdivided") and preset != "marble":
                    continue
                for backend in backends:
                    if (backend == "gpu" and software and not args.all_gpu
                            and (preset != "marble" or name != args.models[0])):
                        continue  # lavapipe: the marble bunny and its subdivided twin only
                    first = args.png if (label == args.models[0] and preset == "marble"
                                         and backend == backends[0]) else None
                    med, splats, pixels = bench(q, u, preset, size, args.runs, backend, first)
                    cells = " | ".join(f"{med[k]:.3f}" for k, _ in PASSES)
                    draw = "" if backend == "cpu" else f"{med['draw']:.3f}"
                    print(f"| {label} | {len(u):,} | {preset} | {backend} | {splats:,} | {pixels:,} | {cells} "
                          f"| {draw} | {med['total']:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
