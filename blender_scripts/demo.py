"""The main job (README: `make demo`), headless in bpy, on a scene it builds itself:
a 10 cm Suzanne with a Subdivision Surface modifier, a point light and a world colour.
The preview uses the default profile, Cycles' random walk with the object's own light.

Exports the evaluated scene through the add-on's exporter, precomputes PRT transport once,
evaluates three of Jensen's measured materials, measures each against the ground truth,
writes the radiance into the add-on's colour attribute, renders it headless as the viewport
shows it (Workbench, flat, colour by attribute: <preset>.png) and renders the same scene with
Cycles' random walk in the mapped Principled BSDF (<preset>_cycles.png), side by side in
<preset>_vs_cycles.png. Prints a table of error and time.

Run: .venv/bin/python blender_scripts/demo.py [--out out/demo] [--presets marble skin1 ketchup]
     [--cycles-samples 64]
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys
import time

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import bpy  # noqa: E402

import translucent  # noqa: E402
from addon import export, writeback  # noqa: E402

MM_PER_UNIT = 1000.0  # Blender units are metres


def build_scene() -> tuple[bpy.types.Object, bpy.types.Object]:
    """A subdivided Suzanne about 10 cm across, a point light, a camera and a dim world."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_monkey_add(size=0.1, location=(0.0, 0.0, 0.0))
    suzanne = bpy.context.active_object
    suzanne.name = "Suzanne"
    mod = suzanne.modifiers.new("Subdivision", "SUBSURF")
    mod.levels = mod.render_levels = 2
    bpy.ops.object.shade_smooth()

    light_data = bpy.data.lights.new("Key", "POINT")
    light_data.energy = 3.0  # W
    light_data.shadow_soft_size = 0.0
    light = bpy.data.objects.new("Key", light_data)
    light.location = (0.12, -0.22, 0.2)
    scene.collection.objects.link(light)

    world = bpy.data.worlds.new("World")
    if world.node_tree is None:  # Blender < 5.0 (5.0 always has nodes; use_nodes is deprecated)
        world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (0.03, 0.03, 0.035, 1.0)
    bg.inputs["Strength"].default_value = 1.0
    scene.world = world

    cam_data = bpy.data.cameras.new("Camera")
    cam = bpy.data.objects.new("Camera", cam_data)
    cam.location = (0.0, -0.32, 0.03)
    cam.rotation_euler = (np.radians(85.0), 0.0, 0.0)
    cam_data.lens = 80
    scene.collection.objects.link(cam)
    scene.camera = cam
    return suzanne, cam


def preview_object(source: bpy.types.Object) -> bpy.types.Object:
    """A separate object holding the evaluated mesh, so the colour attribute can have one value
    per evaluated vertex (the Subdivision modifier changes the vertex count)."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    mesh = bpy.data.meshes.new_from_object(source.evaluated_get(depsgraph))
    obj = bpy.data.objects.new(source.name + " preview", mesh)
    obj.matrix_world = source.matrix_world
    bpy.context.scene.collection.objects.link(obj)
    source.hide_render = True
    mat = bpy.data.materials.new("Translucent preview")
    if mat.node_tree is None:  # Blender < 5.0 (5.0 always has nodes; use_nodes is deprecated)
        mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    attr = nodes.new("ShaderNodeAttribute")
    attr.attribute_name = writeback.ATTRIBUTE
    emit = nodes.new("ShaderNodeEmission")
    out = nodes.new("ShaderNodeOutputMaterial")
    links.new(attr.outputs["Color"], emit.inputs["Color"])
    links.new(emit.outputs["Emission"], out.inputs["Surface"])
    mesh.materials.append(mat)
    return obj


def render(path: pathlib.Path) -> None:
    """The preview as the viewport shows it: Workbench, flat lighting, colour by attribute."""
    scene = bpy.context.scene
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.display.shading.light = "FLAT"
    scene.display.shading.color_type = "VERTEX"
    scene.render.resolution_x = scene.render.resolution_y = 256
    scene.render.film_transparent = False
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)


def render_cycles(source: bpy.types.Object, preview: bpy.types.Object, material, samples: int,
                  path: pathlib.Path) -> None:
    """The same scene in Cycles: the source object (modifiers and all) in a Principled BSDF
    random walk mapped from `material` (translucent.cycles); the preview object hidden."""
    from translucent import cycles

    mat = bpy.data.materials.new("Cycles " + path.stem)
    if mat.node_tree is None:  # Blender < 5.0 (5.0 always has nodes; use_nodes is deprecated)
        mat.use_nodes = True
    cycles.apply_to_principled(
        mat.node_tree.nodes["Principled BSDF"],
        cycles.to_principled(material.sigma_a, material.sigma_s, material.g, material.eta),
    )
    source.data.materials.clear()
    source.data.materials.append(mat)
    source.hide_render, preview.hide_render = False, True
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.render.resolution_x = scene.render.resolution_y = 256
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    source.hide_render, preview.hide_render = True, False


def side_by_side(left: pathlib.Path, right: pathlib.Path, path: pathlib.Path) -> None:
    import matplotlib.image as mpimg

    a, b = mpimg.imread(left), mpimg.imread(right)
    mpimg.imsave(path, np.concatenate([a[..., :3], b[..., :3]], axis=1))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=str(REPO / "out" / "demo"))
    ap.add_argument("--presets", nargs="+", default=["marble", "skin1", "ketchup"])
    ap.add_argument("--receivers", type=int, default=100, help="vertices the ground truth is computed at")
    ap.add_argument("--cycles-samples", type=int, default=64, help="samples of the Cycles render beside each preview")
    args = ap.parse_args()
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows: list[tuple[str, float, str]] = []

    t0 = time.perf_counter()
    suzanne, cam = build_scene()
    scene, info = export.export_scene([suzanne])
    rows.append(("export (evaluated mesh, lights, world)", time.perf_counter() - t0, ""))
    print(f"scene: {scene}, lights {info.lights}, world {info.world}")

    materials = {name: translucent.Material.preset(name, MM_PER_UNIT) for name in args.presets}
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
    preview = preview_object(suzanne)
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
        render(out / f"{name}.png")
        rows.append((f"  render {name}.png (Workbench, the attribute as the viewport shows it)", time.perf_counter() - t0, ""))
        t0 = time.perf_counter()
        render_cycles(suzanne, preview, m, args.cycles_samples, out / f"{name}_cycles.png")
        side_by_side(out / f"{name}.png", out / f"{name}_cycles.png", out / f"{name}_vs_cycles.png")
        rows.append((f"  render {name}_cycles.png (Cycles random walk, {args.cycles_samples} spp)", time.perf_counter() - t0, ""))

    import matplotlib.image as mpimg

    pairs = [mpimg.imread(out / f"{name}_vs_cycles.png")[..., :3] for name in materials]
    mpimg.imsave(out / "preview_vs_cycles.png", np.concatenate(pairs, axis=0))
    print(f"\n{'step':58s} {'seconds':>9s}  error against ground truth (R/G/B)")
    for step, sec, note in rows:
        print(f"{step:58s} {sec:9.4f}  {note}")
    print(f"\nimages in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
