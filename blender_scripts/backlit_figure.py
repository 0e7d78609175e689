"""Suzanne lit from behind, her ears between the light and the camera (issue 12, point 5): the
preview as the viewport shows it for the dipole, for Cycles' half-space table alone, and with
the walks through the mesh, next to a Cycles render of the same Principled material.

Writes docs/backlit_ears.png (four panels, left to right, each named above; the previews with
their distance from the bake) and prints, per preview, its distance from a 1024-spp Cycles
vertex bake (area-weighted relative RMS, worst channel; cached in out/cache).

Run: .venv/bin/python blender_scripts/backlit_figure.py [--material skin1] [--cycles-samples 256]
"""

from __future__ import annotations

import argparse
import pathlib
import sys

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import bpy  # noqa: E402,F401

import translucent  # noqa: E402
from addon import export, writeback  # noqa: E402
from blender_scripts.lib import cycles_reference as cr  # noqa: E402
from blender_scripts.lib import figures, scenes  # noqa: E402
from blender_scripts.lib.metrics import rel  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--material", default="skin1")
    ap.add_argument("--cycles-samples", type=int, default=256)
    ap.add_argument("--bake-spp", type=int, default=1024)
    ap.add_argument("--out", default=str(REPO / "docs" / "backlit_ears.png"))
    args = ap.parse_args(argv)

    suzanne, cam = scenes.build_scene("suzanne-backlit")
    scene, _ = export.export_scene([suzanne])
    m = scenes.material(args.material)
    # The bake first, with the evaluated mesh the only object Cycles sees (as cycles_gap.py bakes
    # it; the cache key holds no other object), then hidden from the renders below.
    bake_obj = scenes.preview_object(suzanne)
    bake_obj.data.materials.clear()
    cyc, _ = cr.bake_vertices(bake_obj, m, args.bake_spp)
    bake_obj.hide_render = True
    preview = scenes.preview_object(suzanne)
    w = scene.vertex_areas[:, 0]
    eye = tuple(cam.location)
    tmp = REPO / "out" / "backlit"
    tmp.mkdir(parents=True, exist_ok=True)
    panels, titles = [], []
    for label, kwargs in (("dipole", dict(profile="dipole", single_scattering=False)), ("half-space table", dict(walks=0)),
                          ("walks through the mesh", dict())):
        prt = translucent.Prt(scene, m, backend="cpu", **kwargs)
        dist = rel(prt.radiance(m), cyc, w)
        print(f"{label:24s} vs Cycles {args.bake_spp} spp bake: {100 * dist:.1f} % "
              f"(precompute {prt.report['seconds']:.1f} s)")
        writeback.write_colors(preview.data, prt.radiance(m, eye))
        preview.data.color_attributes.active_color_name = writeback.ATTRIBUTE
        path = tmp / f"{label.replace(' ', '_')}.png"
        figures.render_preview(path)
        panels.append(path)
        titles.append(f"preview: {label}\n{100 * dist:.1f} % from Cycles' bake")
    cycles_path = tmp / "cycles.png"
    cr.render_beside(suzanne, preview, m, args.cycles_samples, cycles_path)
    panels.append(cycles_path)
    titles.append(f"Cycles random walk\n{args.cycles_samples} spp render, denoised")

    import matplotlib.image as mpimg

    images = [mpimg.imread(p) for p in panels]
    out = pathlib.Path(args.out)
    figures.labelled_grid([images], out, columns=titles,
                          note=f"{args.material}, lit from behind; distance: area-weighted relative RMS over the "
                               f"vertices, worst channel, against a {args.bake_spp}-spp Cycles vertex bake")
    print(f"wrote {out}: dipole | half-space table | walks through the mesh | Cycles {args.cycles_samples} spp")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
