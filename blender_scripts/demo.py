"""The main job (README: `make demo`), headless in bpy, on a scene it builds itself:
a 10 cm Suzanne with a Subdivision Surface modifier, a point light and a world colour.
The preview uses the default profile, Cycles' random walk with the object's own light.

Exports the evaluated scene through the add-on's exporter, precomputes PRT transport once,
evaluates three of Jensen's measured materials, measures each against the ground truth,
writes the radiance into the add-on's colour attribute, renders it headless as the viewport
shows it (Workbench, flat, colour by attribute: <preset>.png) and renders the same scene with
Cycles' random walk in the mapped Principled BSDF (<preset>_cycles.png), side by side in
<preset>_vs_cycles.png, every preset in preview_vs_cycles.png (a row each, the columns and
rows named). Prints a table of error and time.

Run: .venv/bin/python blender_scripts/demo.py [--out out/demo] [--presets marble skin1 ketchup]
     [--cycles-samples 64]
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import bpy  # noqa: E402,F401

import translucent  # noqa: E402
from addon import export, writeback  # noqa: E402
from blender_scripts.lib import cycles_reference, figures, scenes  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=str(REPO / "out" / "demo"))
    ap.add_argument("--presets", nargs="+", default=["marble", "skin1", "ketchup"])
    ap.add_argument("--receivers", type=int, default=100, help="vertices the ground truth is computed at")
    ap.add_argument("--cycles-samples", type=int, default=64, help="samples of the Cycles render beside each preview")
    ap.add_argument("--scene-preset", default="skin1",
                    help="the material of the last row: Suzanne on a floor, a box casting its shadow across her, "
                         "her Base Color from an image through the UV map ('none' leaves the row out)")
    args = ap.parse_args()
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows: list[tuple[str, float, str]] = []

    t0 = time.perf_counter()
    suzanne, cam = scenes.demo_scene()
    scene, info = export.export_scene([suzanne])
    rows.append(("export (evaluated mesh, lights, world)", time.perf_counter() - t0, ""))
    print(f"scene: {scene}, lights {info.lights}, world {info.world}")

    materials = {name: translucent.Material.preset(name, scenes.MM_PER_UNIT) for name in args.presets}
    t0 = time.perf_counter()

    def progress(f: float) -> bool:
        print(f"\rprecompute {100 * f:5.1f} %", end="", flush=True)
        return True

    prt = translucent.Prt(scene, list(materials.values()), coefficients=32, progress=progress)
    print()
    rep = prt.report
    rows.append(
        (f"precompute ({rep['samples']} samples, {rep['coefficients']} coefficients)", time.perf_counter() - t0, "")
    )

    rng = np.random.default_rng(1)
    receivers = np.sort(rng.choice(scene.vertex_count, size=min(args.receivers, scene.vertex_count), replace=False))
    weights = scene.vertex_areas[receivers, 0]
    preview = scenes.preview_object(suzanne)
    eye = tuple(cam.location)
    for name, m in materials.items():
        # The ground truth integrates the half-space profile's direct light: compare PRT without
        # the object's own light and without the walks' geometry term.
        b = prt.radiosity(m, interreflection=False, walks=False)
        edit = prt.last_eval
        t0 = time.perf_counter()
        truth = translucent.reference_radiosity(scene, m, rel_tol=1e-3, receivers=receivers.tolist())
        ref_s = time.perf_counter() - t0
        err = translucent.relative_error(b[receivers], truth, weights)
        fmt = lambda v: "/".join(f"{100 * x:.2f}" for x in v)  # noqa: E731
        rows.append(
            (f"edit {name} (fit + dot, 3 channels)", edit["seconds"],
             f"rms {fmt(err['rms'])} %, max {fmt(err['max'])} % (estimate {fmt(edit['error_estimate'])} %)")
        )
        rows.append((f"  ground truth {name} at {len(receivers)} vertices", ref_s, ""))
        radiance = prt.radiance(m, eye)
        writeback.write_colors(preview.data, radiance)
        preview.data.color_attributes.active_color_name = writeback.ATTRIBUTE
        t0 = time.perf_counter()
        figures.render_preview(out / f"{name}.png")
        rows.append((f"  render {name}.png (Workbench, the attribute as the viewport shows it)", time.perf_counter() - t0, ""))
        t0 = time.perf_counter()
        cycles_reference.render_beside(suzanne, preview, m, args.cycles_samples, out / f"{name}_cycles.png")
        figures.side_by_side(out / f"{name}.png", out / f"{name}_cycles.png", out / f"{name}_vs_cycles.png")
        rows.append((f"  render {name}_cycles.png (Cycles random walk, {args.cycles_samples} spp)", time.perf_counter() - t0, ""))

    names = list(materials)
    if args.scene_preset != "none":
        rows += in_a_scene(suzanne, preview, eye, args.scene_preset, args.cycles_samples, out)
        names.append("scene")

    import matplotlib.image as mpimg

    pairs = [[mpimg.imread(out / f"{name}{kind}.png") for kind in ("", "_cycles")] for name in names]
    figures.labelled_grid(
        pairs, out / "preview_vs_cycles.png",
        columns=["preview: PRT, Cycles' profile\n(vertex colours, as in the viewport)",
                 f"Cycles random walk, same material\n{args.cycles_samples} spp, denoised"],
        rows=list(materials) + ([f"{args.scene_preset}, textured, on a floor"]
                                if args.scene_preset != "none" else []))
    print(f"\n{'step':58s} {'seconds':>9s}  error against ground truth (R/G/B)")
    for step, sec, note in rows:
        print(f"{step:58s} {sec:9.4f}  {note}")
    print(f"\nimages in {out}")
    return 0


def in_a_scene(suzanne, preview, eye, preset: str, samples: int, out: pathlib.Path) -> list[tuple[str, float, str]]:
    """Issue 30's scene: the same Suzanne standing on a floor with a box casting its shadow
    across her (`scenes.floor_and_box`), her Base Color from an image through the UV map
    (`scenes.texture_base_color`), as the add-on previews it: the whole scene exported (the
    floor and the box shadow her and send one bounce back), the Base Color read per vertex by
    Cycles' bake, the transport for its mean, brightest and darkest colour. Writes scene.png,
    scene_cycles.png and scene_vs_cycles.png; returns the table's rows."""
    from addon import textures
    from translucent import cycles

    rows = []
    scenes.floor_and_box(suzanne)
    mat = cycles_reference.principled_material(translucent.Material.preset(preset, scenes.MM_PER_UNIT),
                                               f"{preset} textured")
    scenes.texture_base_color(mat, "image")
    suzanne.data.materials.clear()
    suzanne.data.materials.append(mat)
    t0 = time.perf_counter()
    preview.hide_render, suzanne.hide_render = True, False  # the copy must not shadow her
    bpy.context.view_layer.update()
    scene, info = export.export_scene([suzanne], material=mat)
    preview.hide_render, suzanne.hide_render = False, True
    rows.append((f"export the scene (occluders {', '.join(info.occluders)})", time.perf_counter() - t0, ""))
    baked, texture_s = textures.bake_base_color(mat, [preview])
    colours = baked[preview.name]
    rows.append((f"  Base Color read by Cycles at {len(colours)} vertices", texture_s, ""))
    inputs = cycles.read_principled(mat.node_tree.nodes["Principled BSDF"])
    t0 = time.perf_counter()
    prt = translucent.Prt(scene, textures.representatives(inputs, colours), coefficients=32)
    rows.append((f"  precompute ({prt.report['samples']} samples, walks, one bounce)", time.perf_counter() - t0, ""))
    radiance = prt.radiance(inputs.material(), eye, base_color=colours)
    edit = prt.last_eval
    est = "/".join(f"{100 * x:.2f}" for x in edit["error_estimate"])
    rows.append(("  edit with the Base Color per vertex", edit["seconds"], f"(estimate {est} %)"))
    writeback.write_colors(preview.data, radiance)
    preview.data.color_attributes.active_color_name = writeback.ATTRIBUTE
    t0 = time.perf_counter()
    figures.render_preview(out / "scene.png")
    cycles_reference.render_beside(suzanne, preview, inputs.material(), samples, out / "scene_cycles.png",
                                   bl_material=mat)
    figures.side_by_side(out / "scene.png", out / "scene_cycles.png", out / "scene_vs_cycles.png")
    rows.append(("  render scene.png and scene_cycles.png", time.perf_counter() - t0, ""))
    return rows


if __name__ == "__main__":
    sys.exit(main())
