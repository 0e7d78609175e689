"""Issue 30's artist's scenes measured part by part against Cycles: the demo's Suzanne on a floor
with a box casting its shadow across her, (a) as a lone object, with the other objects as
shadows only, and as shadows that send light back; (b) with a textured Base Color (a procedural
checker, an image through the UV map), read per vertex and as the socket's value alone; (c) a
ball of another material pressed into her cheek, as one medium and as two; (d) her eyes in an
opaque material, every face previewed and the material's faces alone.

Each row is one PRT precompute against a Cycles vertex bake of the whole scene at `spp` with
every sample taken (seed 0; cached in out/cache/cycles): area-weighted relative RMS over the
object's vertices, worst channel. `scene_vs_cycles.py` prints the rows; `report.py` plots them
with the rest of the error-against-run-time report."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import bpy
import numpy as np

import translucent
from addon import export
from blender_scripts.lib import cycles_reference as cr
from blender_scripts.lib import scenes
from blender_scripts.lib.metrics import worst


@dataclass
class Part:
    """One preview of one scene against its Cycles bake."""

    scene: str  # which of issue 30's scenes: "(a) floor and box", ...
    part: str  # what this preview takes into account
    material: str
    obj: str
    rms: float  # area-weighted relative RMS, worst channel
    max: float  # max relative error, worst channel
    estimate: float  # the preview's own error estimate, worst channel
    precompute_s: float
    edit_s: float  # the evaluation after the precompute (the core's seconds)
    bake_s: float  # the Cycles bake's wall time
    vertices: int
    chain: str = ""  # rows of one scene, object and material that build on each other share it


FLOOR = "(a) floor and box"
TEXTURE = "(b) textured Base Color"
TOUCHING = "(c) two characters touching"
SLOTS = "(d) a second, opaque material"


def _preview(scene, m, *, reference, w, mask=None, base_color=None, materials=None, others=None):
    """One precompute of `scene` (for `materials`, else `m`) and its radiance in `m` (with
    `base_color` or `others` per vertex where given), against `reference` over the vertices where
    `mask` holds: (rms, max, estimate, precompute_s, edit_s, vertices compared)."""
    from addon import textures

    t0 = time.perf_counter()
    walked = {} if materials is None else textures.walked(materials)
    prt = translucent.Prt(scene, m if materials is None else materials, backend="cpu", single_scattering=False,
                          **walked)
    precompute = time.perf_counter() - t0
    per_vertex = {k: v for k, v in (("base_color", base_color), ("others", others)) if v is not None}
    preview = prt.radiance(m, **per_vertex)
    edit = float(prt.last_eval["seconds"])
    keep = np.ones(len(preview), bool) if mask is None else mask
    rms, mx = worst(translucent.relative_error(preview[keep], reference[keep], w[keep]))
    return rms, mx, float(max(prt.last_eval["error_estimate"])), precompute, edit, int(keep.sum())


def measure(materials: list[str], spp: int = 1024, *, variants: bool = True, texture: bool = True,
            objects: bool = True, log: Callable[[str], None] = print) -> list[Part]:
    """Every row of the four scenes for `materials` (scenes (c) and (d) take the first two and
    the first), each handed to `log` as it is measured; a new Blender file is built first."""
    parts: list[Part] = []

    def add(part: Part) -> None:
        parts.append(part)
        log(f"{part.scene}, {part.obj} in {part.material}, {part.part}: {100 * part.rms:.2f} % from Cycles "
            f"(estimate {100 * part.estimate:.2f} %), precompute {part.precompute_s:.1f} s, "
            f"edit {1e3 * part.edit_s:.1f} ms; bake {part.bake_s:.0f} s")

    obj, _ = scenes.build_scene("suzanne")
    others = scenes.floor_and_box(obj)
    bpy.context.view_layer.update()
    steps = _floor_variants(obj, others)
    scene = steps[-1][1]
    bake_obj = scenes.preview_object(obj)
    bake_obj.data.materials.clear()
    w = scene.vertex_areas[:, 0]
    log(f"Suzanne (Subdivision 2), {scene.vertex_count} vertices, on a floor with a box in the key light's way; "
        f"Cycles vertex bakes at {spp} spp, every sample")
    for name in materials:
        m = scenes.material(name)
        bake, bake_s = cr.bake_vertices(bake_obj, m, spp, adaptive=False)
        for label, s in steps if variants else ():
            rms, mx, est, pre, edit, n = _preview(s, m, reference=bake, w=w)
            add(Part(FLOOR, label, name, "Suzanne", rms, mx, est, pre, edit, bake_s, n))
        if texture:
            for source in ("procedural", "image"):
                for part in _textured(name, m, bake_obj, scene, w, spp, source):
                    add(part)
    if objects and materials:
        bake_obj.hide_render = True
        if len(materials) >= 2:
            for part in _touching(obj, materials[0], materials[1], spp):
                add(part)
        for part in _eyes(obj, materials[0], spp):
            add(part)
    return parts


def _floor_variants(obj, others) -> list[tuple[str, translucent.Scene]]:
    """Scene (a) exported three ways: Suzanne alone (the other objects hidden from renders),
    the others black (shadows only), and as they are (shadows and the light they send back)."""
    steps = []
    for o in others:
        o.hide_render = True
    bpy.context.view_layer.update()
    steps.append(("lone object (before issue 30)", export.export_scene([obj])[0]))
    for o in others:
        o.hide_render = False
    floor_input = bpy.data.materials["Floor"].node_tree.nodes["Principled BSDF"].inputs["Base Color"]
    floor_input.default_value = (0.0, 0.0, 0.0, 1.0)
    black = bpy.data.materials.new("Black")
    black.diffuse_color = (0.0, 0.0, 0.0, 1.0)
    if black.node_tree is not None:  # Blender 5 gives a new material a Principled BSDF (Base Color 0.8)
        black.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    others[1].data.materials.append(black)
    bpy.context.view_layer.update()
    steps.append(("+ occluders: the floor and the box as shadows only (albedo 0)", export.export_scene([obj])[0]))
    floor_input.default_value = (*scenes.FLOOR_COLOUR, 1.0)
    others[1].data.materials.clear()
    bpy.data.materials.remove(black)
    bpy.context.view_layer.update()
    steps.append(("+ bounce: their albedo sends light back (and the own light off the floor)",
                  export.export_scene([obj])[0]))
    return steps


def _textured(name: str, m, bake_obj, scene, w, spp: int, source: str) -> list[Part]:
    """Scene (a) with the material's Base Color from `source` ("procedural": a Checker Texture;
    "image": soft blotches through the UV map): the socket's value shown uniformly (before
    issue 30) and the texture read per vertex (the add-on's Cycles bake of the Base Color,
    `Prt.radiance(base_color=...)`), against a Cycles bake of the textured material."""
    from addon import textures
    from translucent import cycles

    mat = cr.principled_material(m, f"{name} textured ({source})")
    node = mat.node_tree.nodes["Principled BSDF"]
    scenes.texture_base_color(mat, source)
    bake, bake_s = cr.bake_whole_scene(bake_obj, [mat], spp, f"{name}, Base Color from scenes.texture_base_color "
                                                             f"{source!r}, {cr._material_key(m)}")
    baked, texture_s = textures.bake_base_color(mat, [bake_obj])
    colours = baked[bake_obj.name]
    inputs = cycles.read_principled(node)
    uniform = inputs.material()
    rows = []
    rms, mx, est, pre, edit, n = _preview(scene, uniform, reference=bake, w=w)
    rows.append(Part(TEXTURE, f"{source}: the socket's value shown uniformly (before issue 30)", name, "Suzanne",
                     rms, mx, est, pre, edit, bake_s, n, chain=source))
    rms, mx, est, pre, edit, n = _preview(scene, uniform, reference=bake, w=w, base_color=colours,
                                          materials=textures.representatives(inputs, colours))
    rows.append(Part(TEXTURE, f"+ texture: the {source} read per vertex (its bake {1e3 * texture_s:.0f} ms)", name,
                     "Suzanne", rms, mx, est, pre + texture_s, edit, bake_s, n, chain=source))
    bake_obj.data.materials.clear()
    bpy.data.materials.remove(mat)
    return rows


def _bake(obj, materials, spp: int, label: str) -> tuple[np.ndarray, float]:
    """A bake of `obj`'s evaluated copy standing in for it in the whole scene, every sample
    taken, its slots holding `materials`; then `obj` is back and the copy removed."""
    copy = scenes.preview_object(obj)
    try:
        return cr.bake_whole_scene(copy, materials, spp, label)
    finally:
        obj.hide_render = False
        mesh = copy.data
        bpy.data.objects.remove(copy)
        bpy.data.meshes.remove(mesh)


def _against(scene, info, m, bake, bake_s, scene_name, part, material, obj_name, mask=None) -> Part:
    """`scene` (one object exported with its material) against `bake` (per evaluated vertex)
    over its exported vertices (those where `mask` holds)."""
    vertices = info.objects[0].vertices
    reference = bake if vertices is None else bake[vertices]
    rms, mx, est, pre, edit, n = _preview(scene, m, reference=reference, w=scene.vertex_areas[:, 0], mask=mask)
    return Part(scene_name, part, material, obj_name, rms, mx, est, pre, edit, bake_s, n)


def _one_medium(objs) -> translucent.Scene:
    """`objs` merged into one mesh with no object IDs (light scatters from one into the other,
    as before issue 30), the rest of the scene, the lights and the world as the export has them."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    ps, ts, ns, offset = [], [], [], 0
    for o in objs:
        p, t, n = export.evaluated_mesh_arrays(o, depsgraph)
        ps.append(p)
        ts.append(t + offset)
        ns.append(n)
        offset += len(p)
    scene = translucent.Scene(np.concatenate(ps), np.concatenate(ts), np.concatenate(ns))
    info = export.ExportInfo()
    export.add_occluders(scene, depsgraph, {o.name for o in objs}, info)
    export.add_lights(scene, bpy.context.scene, info)
    export.set_world(scene, bpy.context.scene, info)
    return scene


def _touching(suzanne, first: str, second: str, spp: int) -> list[Part]:
    """Scene (c): a 3 cm ball of the second material pressed 2 mm into Suzanne's right cheek
    (beside her, on the floor's side of the key light). Before object IDs: the two as one medium
    in Suzanne's material (light scatters from the ball into her). With them: each its own
    medium with its own material, the other an occluder, one precompute each, against one
    Cycles bake of the whole scene per object."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    p, _, _ = export.evaluated_mesh_arrays(suzanne, depsgraph)
    side = p[np.abs(p[:, 2]) < 0.01]
    right = side[np.argmax(side[:, 0])]
    r = 0.03
    bpy.ops.mesh.primitive_uv_sphere_add(radius=r, segments=64, ring_count=32,
                                         location=(float(right[0]) + r - 0.002, float(right[1]), float(right[2])))
    sphere = bpy.context.active_object
    sphere.name = "Ball"
    bpy.ops.object.shade_smooth()
    m1, m2 = scenes.material(first), scenes.material(second)
    mat1, mat2 = cr.principled_material(m1, f"{first} (Suzanne)"), cr.principled_material(m2, f"{second} (ball)")
    suzanne.hide_render = False
    suzanne.data.materials.clear()
    suzanne.data.materials.append(mat1)
    sphere.data.materials.append(mat2)
    bpy.context.view_layer.update()
    exports = [export.export_scene([o], material=mat) for o, mat in ((suzanne, mat1), (sphere, mat2))]
    key = f"touching: Suzanne in {first} {cr._material_key(m1)}, the ball in {second} {cr._material_key(m2)}"
    bakes = [_bake(o, [mat], spp, f"{key}, {o.name} baked") for o, mat in ((suzanne, mat1), (sphere, mat2))]
    rows = []
    merged = _one_medium([suzanne, sphere])
    suzanne_bake, suzanne_s = bakes[0]
    n_suzanne = len(exports[0][0].vertex_areas)
    mine = np.zeros(merged.vertex_count, bool)
    mine[:n_suzanne] = True
    reference = np.zeros((merged.vertex_count, 3), np.float32)
    reference[:n_suzanne] = suzanne_bake
    rms, mx, est, pre, edit, n = _preview(merged, m1, reference=reference, w=merged.vertex_areas[:, 0], mask=mine)
    rows.append(Part(TOUCHING, "one medium: the two merged, no object IDs (before issue 30)", first, "Suzanne",
                     rms, mx, est, pre, edit, suzanne_s, n))
    for (o, m, name), (scene, info), (bake, seconds) in zip(((suzanne, m1, first), (sphere, m2, second)),
                                                            exports, bakes):
        rows.append(_against(scene, info, m, bake, seconds, TOUCHING,
                             "+ object IDs: each its own medium and material, the other an occluder", name, o.name))
    suzanne.hide_render = False
    bpy.data.objects.remove(sphere)
    suzanne.data.materials.clear()
    return rows


def _eyes(suzanne, name: str, spp: int) -> list[Part]:
    """Scene (d): Suzanne's eyes (the monkey's two smallest loose parts) in an opaque Principled
    BSDF (Base Color 0.05, no subsurface), the rest in the material. Before issue 30 every face
    scattered and received; now only the material's faces do and the eyes cast shadows.
    Compared over the vertices no eye face touches (a vertex on the seam is baked as the mean
    of both materials)."""
    mesh = suzanne.data
    eyes = scenes.smallest_parts(mesh)
    m = scenes.material(name)
    skin = cr.principled_material(m, f"{name} (Suzanne, eyes apart)")
    eye = bpy.data.materials.new("Eyes")
    if eye.node_tree is None:  # Blender < 5.0
        eye.use_nodes = True
    eye.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.05, 0.05, 0.05, 1.0)
    mesh.materials.clear()
    mesh.materials.append(skin)
    mesh.materials.append(eye)
    mesh.polygons.foreach_set("material_index", eyes.astype(np.int32))
    suzanne.hide_render = False
    bpy.context.view_layer.update()
    scene, info = export.export_scene([suzanne], material=skin)
    bake, seconds = _bake(suzanne, [skin, eye], spp, f"eyes opaque (0.05), Suzanne in {name} {cr._material_key(m)}")
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = suzanne.evaluated_get(depsgraph).to_mesh()
    seam = np.zeros(len(evaluated.vertices), bool)
    for poly in evaluated.polygons:
        if poly.material_index == 1:
            seam[list(poly.vertices)] = True
    suzanne.evaluated_get(depsgraph).to_mesh_clear()
    every, every_info = export.export_scene([suzanne])
    rows = [_against(every, every_info, m, bake, seconds, SLOTS, "every face the material (before issue 30)", name,
                     "Suzanne", mask=~seam)]
    mask = ~seam[info.objects[0].vertices] if info.objects[0].vertices is not None else ~seam
    rows.append(_against(scene, info, m, bake, seconds, SLOTS,
                         "+ material slots: the eyes opaque occluders, not scattering (the hierarchy and "
                         "the splatting)", name, "Suzanne", mask=mask))
    # PRT with the material read from its Principled BSDF: the eyes' faces stay in the mesh as
    # Cycles' walk sees them, their vertices scattering as their own albedo, passed apart from
    # the uniform material (the add-on's `textures.read` beside other materials: `others=`).
    from addon import textures
    from translucent import cycles

    kept, kept_info = export.export_scene([suzanne], material=skin, others_scatter=True)
    inputs = cycles.read_principled(skin.node_tree.nodes["Principled BSDF"])
    colours, previewed = textures.beside_others(inputs.base_color, textures.others_in(kept_info))
    rms, mx, est, pre, edit, n = _preview(kept, inputs.material(), reference=bake, w=kept.vertex_areas[:, 0],
                                          mask=~seam, others=textures.others_in(kept_info),
                                          materials=textures.representatives(inputs, colours, previewed))
    rows.append(Part(SLOTS, "+ the eyes' faces kept in the mesh as Cycles' walk sees them, scattering as their "
                            "own colour (PRT)", name, "Suzanne", rms, mx, est, pre, edit, seconds, n))
    return rows
