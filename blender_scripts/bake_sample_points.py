"""Where Cycles' vertex bake samples: an open 10 cm sheet under a sun, its 1024-spp vertex bake
against the walk reference entering at the bake's sample points and at the vertices, along a
row from the sheet's edge inwards.

Blender bakes a vertex colour as the mean over its corners of Cycles' answer at a point moved
from the vertex towards the corner triangle's centroid by min(that distance,
1e-4 * max(1, largest |coordinate|)) (`bake_offset_towards_center`). At the sheet's edge the
radiance changes within that offset; a row of vertices shows where the bake and the reference
part. `--origin X` moves the sheet X metres along x (the offset grows with |coordinate|).

Run: .venv/bin/python blender_scripts/bake_sample_points.py [--material aniso08] [--origin 0]
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import bpy  # noqa: E402

import translucent  # noqa: E402
from blender_scripts.lib import cycles_reference, scenes  # noqa: E402

SIZE = scenes.SHEET_SIZE  # the sheet's side [m]


def main(argv=None) -> int:
    from addon import export

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--material", default="aniso08")
    ap.add_argument("--origin", type=float, default=0.0)
    ap.add_argument("--vertices", type=int, default=41, help="per side of the sheet")
    args = ap.parse_args(argv)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    n = args.vertices
    obj = scenes.sheet(n, SIZE, args.origin)
    scene, _ = export.export_scene([obj])
    m = scenes.material(args.material)
    row = [n // 2 * n + i for i in range(6)]
    cyc, seconds = cycles_reference.bake_vertices(obj, m, 1024)
    ref = translucent.reference_radiance(scene, m, walks=4096, receivers=row)
    at_vertex = translucent.reference_radiance(scene, m, walks=4096, receivers=row, at="vertex")
    print(f"{args.material}, sheet's edge at x = {args.origin} m, bake {seconds:.0f} s")
    for k, v in enumerate(row):
        d = 1000 * SIZE * k / (n - 1)
        print(f"  {d:5.2f} mm from the edge: bake {np.round(cyc[v], 4)}  walk reference at the bake points "
              f"{np.round(ref[k], 4)} (ratio {np.round(cyc[v] / ref[k], 3)}), at the vertex {np.round(at_vertex[k], 4)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
