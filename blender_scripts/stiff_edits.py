"""How far fixed knots hold (issue 5, point 5): precompute once for a material, then edit its
coefficients by a factor k (sigma_a and sigma_s both times k: the same albedo, a profile k times
narrower) without a new precompute, and compare with the ground truth. Prints, per factor,
the PRT's own error estimate next to the measured area-weighted relative RMS and max error.

Run: .venv/bin/python blender_scripts/stiff_edits.py [--receivers 60] [--material marble]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from blender_scripts.lib import models  # noqa: E402

import translucent  # noqa: E402

FACTORS = (0.01, 0.1, 0.3, 1.0, 3.0, 10.0, 100.0, 1000.0)


def scaled(m: translucent.Material, k: float) -> translucent.Material:
    return translucent.Material(
        tuple(k * x for x in m.sigma_a), tuple(k * x for x in m.sigma_s), g=m.g, eta=m.eta
    )


def measure(model: str, material: str, receivers: int, factors=FACTORS, rel_tol: float = 2e-3,
            refresh_check: bool = True) -> list[dict]:
    p, t = models.load(model, diagonal=0.1)
    scene = models.standard_scene(p, t)
    base = translucent.Material.preset(material, mm_per_unit=1000.0)
    # The half-space transport against its own ground truth: no walks through the mesh.
    prt = translucent.Prt(scene, base, walks=0)
    rng = np.random.default_rng(3)
    idx = np.sort(rng.choice(scene.vertex_count, size=min(receivers, scene.vertex_count), replace=False))
    weights = scene.vertex_areas[idx, 0]
    # On an open rim (the bunny has holes) only the covered share of the disc is surface.
    irr = (scene.irradiance(eta=base.eta) * scene.vertex_coverage[:, None])[idx]
    rows = []
    for k in factors:
        m = scaled(base, k)
        b = prt.radiosity(m)[idx]
        est = prt.last_eval["error_estimate"]
        advised = prt.refresh_advised
        t0 = time.perf_counter()
        ref, info = translucent.reference_radiosity(scene, m, rel_tol=rel_tol, receivers=idx.tolist(), details=True)
        ref_s = time.perf_counter() - t0
        err = translucent.relative_error(b, ref, weights)
        # The limit sigma_t -> infinity is exact: B = c I(x) R_d,total (Jensen 2001's diffuse
        # limit; c the vertex's coverage, 1 inside the surface).
        limit = translucent.relative_error(b, irr * np.array(m.total_diffuse_reflectance), weights)
        fresh = translucent.Prt(scene, m, walks=0).radiosity(m)[idx] if refresh_check else None
        fresh_err = max(translucent.relative_error(fresh, ref, weights)["rms"]) if refresh_check else float("nan")
        rows.append(dict(factor=k, rms=max(err["rms"]), max=max(err["max"]), estimate=max(est),
                         refresh=advised, reference_s=ref_s, reference_error=info["estimated_rel_error"],
                         converged=info["converged"], limit_rms=max(limit["rms"]), fresh_rms=fresh_err))
        print(f"  k={k:g}: rms {100 * max(err['rms']):.2f} %, estimate {100 * max(est):.2f} %, "
              f"refresh advised {advised} ({ref_s:.0f} s)", file=sys.stderr)
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", default="stanford-bunny.obj")
    ap.add_argument("--material", default="marble")
    ap.add_argument("--receivers", type=int, default=60)
    args = ap.parse_args()
    rows = measure(args.model, args.material, args.receivers)
    print(f"{args.model} at 10 cm, knots and samples chosen for {args.material}; "
          f"edit = sigma_a and sigma_s times k; {args.receivers} receivers")
    print("| k | rel. RMS vs reference % | reference's own estimate % | rel. RMS vs diffuse limit % "
          "| PRT estimate % | refresh advised | after refresh: rel. RMS vs reference % |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        conv = "" if r["converged"] else " (level cap)"
        print(f"| {r['factor']:g} | {100 * r['rms']:.2f} | {100 * r['reference_error']:.2f}{conv} | "
              f"{100 * r['limit_rms']:.2f} | {100 * r['estimate']:.2f} | {'yes' if r['refresh'] else 'no'} | "
              f"{100 * r['fresh_rms']:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
