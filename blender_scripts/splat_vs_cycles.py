"""The splatting's camera image against a Cycles render of the same camera (issue 31's second
done-when): the demo's Suzanne (10 cm, Subdivision 2) under its point light and its dim world
(`--world black` drops the world), the Principled BSDF random walk mapped from the material with
its specular layer off (Specular IOR Level 0), 128 x 128, 1024 spp, no denoising.
Against that one image, object pixels, relative RMS worst channel (`metrics.image_error`):

- `Splat.render` (Cycles' profile), with eps as the knob at the default 1024 grid, and at the
  grids Shah's Fig. 12 uses (8, 16 and 32 a side) at eps 0.01; and with the walks' term and
  the object's own light (`walks=True`), walked at the first render and kept for the next;
- the per-vertex preview (PRT, Cycles' profile, with its walks and own light), shown as the
  viewport shows it (the vertex colours as emission, rendered by Cycles at 16 spp: the
  interpolation across the faces is Blender's own);
- EEVEE's own subsurface scattering at 64 samples (skipped, saying why, where it cannot run).

Each with its wall time. Run: .venv/bin/python blender_scripts/splat_vs_cycles.py [--material
marble] [--size 128] [--spp 1024] [--world demo|black].
"""

from __future__ import annotations

import argparse
import math
import pathlib
import sys
import time

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import bpy  # noqa: E402

import translucent  # noqa: E402
from translucent import cycles  # noqa: E402
from addon import export, writeback  # noqa: E402
from blender_scripts.lib import cycles_reference as cr  # noqa: E402
from blender_scripts.lib import scenes  # noqa: E402
from blender_scripts.lib.machine import describe as machine  # noqa: E402
from blender_scripts.lib.metrics import image_error  # noqa: E402


def render(engine: str, samples: int, size: int) -> tuple[np.ndarray, float]:
    """The scene's camera at `size` square through `engine`, transparent film: RGBA, seconds."""
    scene = cr.use_engine(engine, samples)
    scene.render.film_transparent = True
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    t0 = time.perf_counter()
    img = cr.render_exr(scene)
    return img, time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--material", default="marble")
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--world", choices=["demo", "black"], default="demo")
    args = ap.parse_args()

    obj, cam = scenes.build_scene("suzanne")
    bl_scene = bpy.context.scene
    if args.world == "black":
        bl_scene.world = None
    scene, info = export.export_scene([obj])
    # The material both sides render: the preset as Cycles' Principled BSDF with its specular
    # layer off (Specular IOR Level 0), read back as a translucent.Material with that layer off
    # too (its exit weight then leaves the subsurface lobe whole, as Cycles does).
    p = cycles.principled_for(translucent.Material.preset(args.material, scenes.MM_PER_UNIT))
    p.specular_ior_level = 0.0
    m = p.material()
    shown = scenes.preview_object(obj)  # the evaluated mesh, the attribute as emission

    # Cycles: the source in the mapped Principled BSDF, its specular layer off.
    mat = bpy.data.materials.new("Cycles reference")
    if mat.node_tree is None:  # Blender < 5.0
        mat.use_nodes = True
    cycles.apply_to_principled(mat.node_tree.nodes["Principled BSDF"], p)
    assert mat.node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value == 0.0
    obj.data.materials.clear()
    obj.data.materials.append(mat)
    obj.hide_render, shown.hide_render = False, True
    truth, truth_s = render("CYCLES", args.spp, args.size)
    rows = [("Cycles random walk", f"{args.spp} spp", "(the reference)", truth_s)]
    try:
        img, s = render("EEVEE", 64, args.size)
        rms, _ = image_error(img, truth)
        rows.append(("EEVEE", "64 samples", f"{100 * rms:.2f}", s))
    except RuntimeError as e:
        rows.append(("EEVEE", "64 samples", f"not run: {e}", float("nan")))
    obj.hide_render, shown.hide_render = True, False

    # The per-vertex preview, as the viewport shows it.
    t0 = time.perf_counter()
    prt = translucent.Prt(scene, [m], profile="cycles")
    pre = time.perf_counter() - t0
    colors = prt.radiance(m)
    writeback.write_colors(shown.data, colors)
    img, _ = render("CYCLES", 16, args.size)
    rms, _ = image_error(img, truth)
    rows.append(("PRT per-vertex preview (Cycles' profile, walks)", "32 coefficients", f"{100 * rms:.2f}",
                 pre + prt.last_eval["seconds"]))
    shown.hide_render = True

    # The splatting's image of the same camera.
    mw = np.array(cam.matrix_world, dtype=np.float64)
    eye = mw[:3, 3]
    view = dict(eye=tuple(eye), target=tuple(eye - mw[:3, 2]), up=tuple(mw[:3, 1]), fov=float(cam.data.angle),
                size=(args.size, args.size))
    runs = [(eps, grid, False) for eps, grid in [(0.1, 1024), (0.03, 1024), (0.01, 1024), (0.003, 1024), (0.01, 8),
                                                (0.01, 16), (0.01, 32)]]
    for eps, grid, walks in runs + [(0.01, 1024, True), (0.003, 1024, True)]:
        splat = translucent.Splat(scene, profile="cycles", eps=eps, max_grid=grid, walks=walks)
        t0 = time.perf_counter()
        image, mask = splat.render(m, **view)
        s = time.perf_counter() - t0
        rgba = np.concatenate([image, (mask > 0)[..., None].astype(np.float32)], axis=2)
        rms, _ = image_error(rgba, truth)
        label = "with the walks' term and own light (walked at this first render)" if walks else "no walks"
        rows.append((f"Splat.render (Cycles' profile, {label})", f"eps {eps:g}, grid {grid}", f"{100 * rms:.2f}", s))
        if walks:
            t0 = time.perf_counter()
            splat.render(m, **view)
            rows.append(("Splat.render, walks kept (a second render)", f"eps {eps:g}, grid {grid}",
                         f"{100 * rms:.2f}", time.perf_counter() - t0))

    print(f"machine: {machine()}; Suzanne (demo scene, world {args.world}: {info.world}), {args.material}, {args.size} x {args.size}, "
          f"against Cycles {args.spp} spp (specular off), object pixels")
    print("| method | setting | rel. RMS % (worst channel) | seconds |")
    print("|---|---|---|---|")
    for method, setting, rms, s in rows:
        print(f"| {method} | {setting} | {rms} | {s:.2f} |" if not math.isnan(s) else f"| {method} | {setting} | {rms} | |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
