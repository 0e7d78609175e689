"""PRT against the ground truth (issue 3, point 6): the Stanford bunny scaled to 10 cm, marble,
skin1 and ketchup at 32 coefficients; area-weighted relative RMS and max relative error per
channel over a random subset of receiver vertices (the reference is the slow part).

Run: .venv/bin/python blender_scripts/accuracy_prt.py [--receivers 400] [--model NAME] [--profile dipole]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
import models  # noqa: E402

import translucent  # noqa: E402

PRESETS = ("marble", "skin1", "ketchup")


def evaluate(model: str, receivers: int, coefficients: int, rel_tol: float, seed: int = 7,
             profile: str = "cycles") -> list[dict]:
    p, t = models.load(model, diagonal=0.1)
    scene = models.standard_scene(p, t)
    mats = {name: translucent.Material.preset(name, mm_per_unit=1000.0) for name in PRESETS}
    rng = np.random.default_rng(seed)
    idx = np.sort(rng.choice(scene.vertex_count, size=min(receivers, scene.vertex_count), replace=False))
    weights = scene.vertex_areas[idx, 0]
    rows = []
    for name, m in mats.items():
        t0 = time.perf_counter()
        # The ground truth integrates the direct-light model: PRT without the object's own light.
        prt = translucent.Prt(scene, m, coefficients=coefficients, profile=profile, interreflection=False,
                              walks=0 if profile == "cycles" else None)
        pre = time.perf_counter() - t0
        b = prt.radiosity(m)[idx]
        edit = prt.last_eval["seconds"]
        t0 = time.perf_counter()
        ref, info = translucent.reference_radiosity(scene, m, rel_tol=rel_tol, receivers=idx.tolist(), details=True,
                                                    profile=profile)
        ref_s = time.perf_counter() - t0
        err = translucent.relative_error(b, ref, weights)
        rows.append(
            dict(material=name, rms=err["rms"], max=err["max"], precompute_s=pre, edit_ms=1e3 * edit,
                 reference_s=ref_s, reference_error=info["estimated_rel_error"],
                 reference_level=info["level"], estimate=prt.last_eval["error_estimate"])
        )
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", default="stanford-bunny.obj")
    ap.add_argument("--receivers", type=int, default=400)
    ap.add_argument("--coefficients", type=int, default=32)
    ap.add_argument("--rel-tol", type=float, default=1e-3)
    ap.add_argument("--profile", default="cycles", choices=["cycles", "dipole"])
    args = ap.parse_args()
    rows = evaluate(args.model, args.receivers, args.coefficients, args.rel_tol, profile=args.profile)
    print(f"{args.model} at 10 cm, {args.profile} profile, {args.coefficients} coefficients, {args.receivers} receivers")
    print("| material | rel. RMS (R, G, B) % | max rel. (R, G, B) % | PRT estimate % | precompute s | edit ms | reference s (level, est. err %) |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        f = lambda v: ", ".join(f"{100 * x:.2f}" for x in v)  # noqa: E731
        print(
            f"| {r['material']} | {f(r['rms'])} | {f(r['max'])} | {f(r['estimate'])} | {r['precompute_s']:.2f} | "
            f"{r['edit_ms']:.2f} | {r['reference_s']:.1f} ({r['reference_level']}, {100 * r['reference_error']:.2f}) |"
        )
    worst = max(max(r["rms"]) for r in rows)
    print(f"worst channel rel. RMS: {100 * worst:.2f} % (target < 1 %)")
    return 0 if worst < 0.01 else 1


if __name__ == "__main__":
    raise SystemExit(main())
