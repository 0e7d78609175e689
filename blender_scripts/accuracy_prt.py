"""PRT against the ground truth (issue 3, point 6): the Stanford bunny scaled to 10 cm, marble,
skin1 and ketchup at 32 coefficients; area-weighted relative RMS and max relative error per
channel over a random subset of receiver vertices (the reference is the slow part).

Run: .venv/bin/python blender_scripts/accuracy_prt.py [--receivers 400] [--model NAME] [--profile dipole]
"""

from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from blender_scripts.lib.accuracy import evaluate  # noqa: E402


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
