"""PRT's walks on a coarse character (issue 29): shared models decimated by Blender to about
3,000 vertices at 20 cm, so that faces are as wide as the diffusion length, previewed by PRT
(Cycles' profile, the walks through the mesh, direct light) and compared vertex by vertex with
the project's walk reference (`reference_radiance`, 1024 walks a vertex) at the same vertices.
Prints, per model and material, the area-weighted relative RMS (per channel), the reference's
own noise, that error beyond the noise (sqrt(rms^2 - noise^2)), PRT's own estimate and both
run times. The bar: within 2 % beyond the reference's noise.

Run: .venv/bin/python blender_scripts/coarse_vs_reference.py [--models ogre.obj,stanford-bunny.obj]
     [--materials skin1,marble] [--walk-rays N] [--reference-walks 1024]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from blender_scripts.lib import models  # noqa: E402
from blender_scripts.lib.machine import describe as machine  # noqa: E402

import translucent  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--models", default="ogre.obj,stanford-bunny.obj")
    ap.add_argument("--materials", default="skin1,marble")
    ap.add_argument("--vertices", type=int, default=3000, help="decimate to about this many vertices")
    ap.add_argument("--diagonal", type=float, default=0.2, help="bounding-box diagonal [m]")
    ap.add_argument("--walk-rays", type=int, default=None, help="PRT's walk budget (default: the Prt default)")
    ap.add_argument("--reference-walks", type=int, default=1024)
    args = ap.parse_args()
    print(f"machine: {machine()}")
    for name in args.models.split(","):
        p, t = models.load(name, diagonal=args.diagonal)
        p, t = models.decimate(p, t, args.vertices)
        scene = models.standard_scene(p, t)
        for material in args.materials.split(","):
            m = translucent.Material.preset(material, mm_per_unit=1000.0)
            t0 = time.perf_counter()
            ref, d = translucent.reference_radiance(scene, m, walks=args.reference_walks, details=True)
            t_ref = time.perf_counter() - t0
            t0 = time.perf_counter()
            prt = translucent.Prt(scene, m, single_scattering=False, interreflection=False,
                                  walk_rays=args.walk_rays)
            t_prt = time.perf_counter() - t0
            rms = np.array(translucent.relative_error(prt.radiance(m), ref, scene.vertex_areas)["rms"])
            noise = np.array(d["noise"])
            beyond = np.sqrt(np.maximum(rms**2 - noise**2, 0.0))
            w = prt.report["walks"]
            pct = lambda x: " / ".join(f"{100 * v:.2f}" for v in x)  # noqa: E731
            print(
                f"{name} at {100 * args.diagonal:.0f} cm, {scene.vertex_count} vertices, {material}: "
                f"PRT {pct(rms)} % from the reference (its noise {pct(noise)} %; beyond it {pct(beyond)} %) "
                f"[bar 2 %]; PRT's estimate {pct(prt.last_eval['error_estimate'])} %; "
                f"precompute {t_prt:.1f} s ({w['rays'] / 1e6:.1f} M walk rays, {w['walked_vertices']} vertices walked, "
                f"{w['sharp_vertices']} sharp), reference {t_ref:.1f} s",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
