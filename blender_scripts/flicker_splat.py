"""Frame-to-frame flicker of the splatting (Shah 2009 §Reducing Temporal Artifacts; issue 31
point 5): per-vertex B over a slow light sweep (a sun turning 0.2 degrees a frame) and a slow
rotation (the object turning 0.2 degrees a frame under a fixed sun), on a 1 cm marble sphere and
the 10 cm bunny, without and with the reuse of earlier frames' samples (`Splat(reuse=True)`).
Flicker is the RMS over vertices and frames of B's second difference B(k+1) - 2 B(k) + B(k-1),
relative to the mean B: a smooth change leaves it near 0 (the sun's own curvature over 0.2
degrees is under 1e-5), a jumpy one does not. The last column: the reused last frame against a
fresh splatting of the same scene (area-weighted relative RMS, worst channel).

Run: .venv/bin/python blender_scripts/flicker_splat.py [--frames N] [--grid G]
"""

from __future__ import annotations

import argparse
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from blender_scripts.lib import models  # noqa: E402
from blender_scripts.lib.machine import describe as machine  # noqa: E402

import translucent  # noqa: E402


def rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def sun_scene(p, t, direction) -> translucent.Scene:
    s = translucent.Scene(p, t)
    s.add_sun(tuple(direction), 3.0)
    return s


def flicker(frames: list[np.ndarray], w: np.ndarray) -> float:
    """RMS of the second difference over vertices (area-weighted) and frames, over the mean B."""
    b = np.stack(frames)  # (K, N, 3)
    d2 = b[2:] - 2 * b[1:-1] + b[:-2]
    mean = float(np.average(b.mean(axis=(0, 2)), weights=w))
    rms = math.sqrt(float(np.average((d2 ** 2).mean(axis=(0, 2)), weights=w)))
    return rms / mean


def run(p, t, m, frames: int, grid: int, kind: str, step_deg: float, reuse: bool) -> tuple[float, float]:
    """The flicker, and the last frame's distance (area-weighted relative RMS, worst channel) from
    a fresh splatting of the same scene."""
    base = np.array([0.4, 0.3, -1.0])
    splat = translucent.Splat(sun_scene(p, t, base), profile="cycles", max_grid=grid, backend="cpu", reuse=reuse)
    fresh = translucent.Splat(sun_scene(p, t, base), profile="cycles", max_grid=grid, backend="cpu")
    w = sun_scene(p, t, base).vertex_areas[:, 0]
    out = []
    for k in range(frames):
        a = math.radians(step_deg * k)
        if kind == "light sweep":
            change = dict(lights=sun_scene(p, t, rot_z(a) @ base))
        else:  # the object turns about its centre under the fixed sun
            c = 0.5 * (p.min(axis=0) + p.max(axis=0))
            change = dict(positions=((p - c) @ rot_z(a).T + c).astype(np.float32))
        splat.update(**change)
        out.append(splat.radiosity(m))
    fresh.update(**change)
    drift = max(translucent.relative_error(out[-1], fresh.radiosity(m), w)["rms"])
    return flicker(out, w), drift


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--grid", type=int, default=1024)
    ap.add_argument("--step", type=float, default=0.2, help="degrees a frame")
    ap.add_argument("--meshes", nargs="+", default=["sphere", "bunny"])
    args = ap.parse_args()
    print(f"machine: {machine()}; grid {args.grid}, {args.frames} frames of {args.step} degrees, Cycles' profile")
    cases = [("sphere 1 cm", *models.uv_sphere(24, 48, 0.005)), ("bunny 10 cm", *models.load("stanford-bunny.obj", diagonal=0.1))]
    cases = [c for c in cases if c[0].split()[0] in args.meshes]
    m = translucent.Material.preset("marble", mm_per_unit=1000.0)
    print("| mesh | motion | flicker without reuse | with reuse | ratio | last frame with reuse vs a fresh frame |")
    print("|---|---|---|---|---|---|")
    for name, p, t in cases:
        for kind in ("light sweep", "rotation"):
            off, _ = run(p, t, m, args.frames, args.grid, kind, args.step, False)
            on, drift = run(p, t, m, args.frames, args.grid, kind, args.step, True)
            print(f"| {name} | {kind} | {100 * off:.3f} % | {100 * on:.3f} % | {on / off:.2f} | {100 * drift:.2f} % |",
                  flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
