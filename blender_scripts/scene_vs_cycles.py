"""The preview in an artist's scene against Cycles (issue 30): the demo's Suzanne standing on a
floor, a box between her and the key light casting its shadow across her, compared with a
Cycles vertex bake of the whole scene (every sample taken). Rows split by what each part adds
(`blender_scripts/lib/scene_parts.py`): (a) the lone object as the preview saw it before issue
30, the other objects as shadows only (black), and as shadows that send light back (their own
albedo); (b) a textured Base Color (a procedural checker, an image through the UV map), the
socket's value alone and read per vertex; (c) a ball of another material touching Suzanne, as
one medium and with object IDs; (d) her eyes in an opaque material, every face previewed and the
material's faces alone. `make report` plots the same rows against run time.

Prints each preview against the bake with its own estimate, precompute and edit times
(area-weighted relative RMS over the object's vertices, worst channel). Bakes are cached
(out/cache/cycles), so a second run only recomputes the previews.

Run: .venv/bin/python blender_scripts/scene_vs_cycles.py [--materials marble skin1] [--spp 1024]
"""

from __future__ import annotations

import argparse
import pathlib
import sys

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import bpy  # noqa: E402,F401

from blender_scripts.lib import scene_parts  # noqa: E402
from blender_scripts.lib.machine import describe as machine  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--materials", nargs="+", default=["marble", "skin1"])
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--texture", action=argparse.BooleanOptionalAction, default=True,
                    help="also the scene with a textured Base Color (issue 30, point 2)")
    ap.add_argument("--variants", action=argparse.BooleanOptionalAction, default=True,
                    help="the uniform material's rows (lone object, shadows only, one bounce)")
    ap.add_argument("--objects", action=argparse.BooleanOptionalAction, default=True,
                    help="also a second character of another material touching Suzanne (two materials "
                         "named), and Suzanne's eyes in an opaque material (issue 30, points 3 and 4)")
    args = ap.parse_args(argv)
    print(f"machine: {machine()}")
    scene_parts.measure(args.materials, args.spp, variants=args.variants, texture=args.texture,
                        objects=args.objects, log=lambda line: print(line, flush=True))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
