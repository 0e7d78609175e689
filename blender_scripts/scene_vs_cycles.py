"""The preview in an artist's scene against Cycles (issue 30): the demo's Suzanne standing on a
floor, a box between her and the key light casting its shadow across her, compared with a
Cycles vertex bake of the whole scene (every sample taken). Rows split by what each part adds:
the lone object as the preview saw it before issue 30 (no other object), the other objects as
shadows only (black), and as shadows that send light back (their own albedo); then the same
scene with a textured Base Color (a procedural checker, and an image through the UV map), read
per vertex and as the socket's value alone.

For each material it prints the three previews against the bake and each one's precompute time
(area-weighted relative RMS over every vertex, worst channel). Bakes are cached
(out/cache/cycles), so a second run only recomputes PRT.

Run: .venv/bin/python blender_scripts/scene_vs_cycles.py [--materials marble skin1] [--spp 1024]
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import bpy  # noqa: E402

import translucent  # noqa: E402
from addon import export  # noqa: E402
from blender_scripts.lib import cycles_reference as cr  # noqa: E402
from blender_scripts.lib import scenes  # noqa: E402
from blender_scripts.lib.machine import describe as machine  # noqa: E402
from blender_scripts.lib.metrics import rel  # noqa: E402

def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--materials", nargs="+", default=["marble", "skin1"])
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--texture", action=argparse.BooleanOptionalAction, default=True,
                    help="also the scene with a textured Base Color (issue 30, point 2)")
    ap.add_argument("--variants", action=argparse.BooleanOptionalAction, default=True,
                    help="the uniform material's rows (lone object, shadows only, one bounce)")
    ap.add_argument("--objects", action=argparse.BooleanOptionalAction, default=True,
                    help="also a second character of another material touching Suzanne, and "
                         "Suzanne's eyes in an opaque material (issue 30, points 3 and 4)")
    args = ap.parse_args(argv)
    print(f"machine: {machine()}")
    obj, _ = scenes.build_scene("suzanne")
    others = scenes.floor_and_box(obj)
    bpy.context.view_layer.update()
    variants = {}
    for o in others:
        o.hide_render = True
    bpy.context.view_layer.update()
    variants["lone object (before issue 30)"] = export.export_scene([obj])[0]
    for o in others:
        o.hide_render = False
    floor_input = bpy.data.materials["Floor"].node_tree.nodes["Principled BSDF"].inputs["Base Color"]
    floor_input.default_value = (0.0, 0.0, 0.0, 1.0)
    box_mat = bpy.data.materials.new("Black")
    others[1].data.materials.append(box_mat)
    box_mat.diffuse_color = (0.0, 0.0, 0.0, 1.0)
    bpy.context.view_layer.update()
    variants["shadows only (albedo 0)"] = export.export_scene([obj])[0]
    floor_input.default_value = (*scenes.FLOOR_COLOUR, 1.0)
    others[1].data.materials.clear()
    bpy.context.view_layer.update()
    scene, info = export.export_scene([obj])
    variants["shadows and one bounce"] = scene
    print(f"Suzanne (Subdivision 2), {scene.vertex_count} vertices, on a floor with a box in the key light's way; "
          f"occluders {info.occluders}, {scene.occluders}; Cycles vertex bakes at {args.spp} spp, every sample")
    bake_obj = scenes.preview_object(obj)
    bake_obj.data.materials.clear()
    w = scene.vertex_areas[:, 0]
    for name in args.materials:
        m = scenes.material(name)
        bake, bake_s = cr.bake_vertices(bake_obj, m, args.spp, adaptive=False)
        for label, s in variants.items() if args.variants else ():
            t0 = time.perf_counter()
            prt = translucent.Prt(s, m, backend="cpu", single_scattering=False)
            seconds = time.perf_counter() - t0
            preview = prt.radiance(m)
            est = 100 * max(prt.last_eval["error_estimate"])
            print(f"{name}, {label}: {100 * rel(preview, bake, w):.2f} % from Cycles (estimate {est:.2f} %), "
                  f"precompute {seconds:.1f} s; bake {bake_s:.0f} s", flush=True)
        if args.texture:
            for source in ("procedural", "image"):
                textured_row(name, m, bake_obj, scene, w, args.spp, source)
    if args.objects and len(args.materials) >= 2:
        bake_obj.hide_render = True
        touching_row(obj, *args.materials[:2], args.spp)
        eyes_row(obj, args.materials[0], args.spp)
    return 0


def textured_row(name: str, m, bake_obj, scene, w, spp: int, source: str) -> None:
    """The same scene with the material's Principled BSDF given a textured Base Color: a
    procedural (a Checker Texture in object space: its own colour and half of it) or an image
    through Suzanne's UV map (a 128 px float image of soft blotches between the colour and half
    of it). The preview reading it per vertex (`Prt.radiance(base_color=...)`, the add-on's
    Cycles bake of the Base Color) and the socket's own value shown uniformly (before issue 30),
    against a Cycles bake of the textured material."""
    from addon import textures
    from translucent import cycles

    mat = cr.principled_material(m, f"{name} textured ({source})")
    node = mat.node_tree.nodes["Principled BSDF"]
    scenes.texture_base_color(mat, source)
    bake, bake_s = _bake_every_sample(bake_obj, [mat], spp)
    baked, texture_s = textures.bake_base_color(mat, [bake_obj])
    colours = baked[bake_obj.name]
    inputs = cycles.read_principled(node)
    t0 = time.perf_counter()
    prt = translucent.Prt(scene, textures.representatives(inputs, colours), backend="cpu", single_scattering=False)
    seconds = time.perf_counter() - t0
    preview = prt.radiance(inputs.material(), base_color=colours)
    est = 100 * max(prt.last_eval["error_estimate"])
    print(f"{name}, Base Color from {source}, read per vertex: {100 * rel(preview, bake, w):.2f} % from Cycles "
          f"(estimate {est:.2f} %), precompute {seconds:.1f} s, the Base Color's bake {1000 * texture_s:.0f} ms; "
          f"bake {bake_s:.0f} s", flush=True)
    uniform = translucent.Prt(scene, inputs.material(), backend="cpu", single_scattering=False).radiance(inputs.material())
    print(f"{name}, Base Color from {source}, the socket's value shown uniformly (before issue 30): "
          f"{100 * rel(uniform, bake, w):.2f} % from Cycles", flush=True)
    bake_obj.data.materials.clear()


def _compare(label: str, scene, info, m, bake, seconds: float, mask=None) -> None:
    """Prints the preview of `scene` (one object, exported with its material) against
    `bake` (per evaluated vertex), over its exported vertices (those where `mask` holds)."""
    vertices = info.objects[0].vertices
    reference = bake if vertices is None else bake[vertices]
    t0 = time.perf_counter()
    prt = translucent.Prt(scene, m, backend="cpu", single_scattering=False)
    precompute = time.perf_counter() - t0
    preview = prt.radiance(m)
    keep = np.ones(len(preview), bool) if mask is None else mask
    w = scene.vertex_areas[:, 0]
    est = 100 * max(prt.last_eval["error_estimate"])
    print(f"{label}: {100 * rel(preview[keep], reference[keep], w[keep]):.2f} % from Cycles over {keep.sum()} "
          f"vertices (estimate {est:.2f} %), precompute {precompute:.1f} s; bake {seconds:.0f} s", flush=True)


def _bake_every_sample(copy, materials, spp: int) -> tuple[np.ndarray, float]:
    """Cycles' diffuse bake (direct, indirect, colour) of `copy` (a mesh without modifiers) at
    `spp`, every sample taken, its slots holding `materials`; and its wall time [s]."""
    copy.data.materials.clear()
    for mat in materials:
        copy.data.materials.append(mat)
    scene_bl = cr.use_cycles(spp, 0)
    scene_bl.cycles.use_adaptive_sampling = False
    t0 = time.perf_counter()
    bake = cr.bake_diffuse_vertex_colors(copy, {"DIRECT", "INDIRECT", "COLOR"})
    return bake, time.perf_counter() - t0


def _bake(obj, materials, spp: int) -> tuple[np.ndarray, float]:
    """A bake at `spp` of `obj`'s evaluated copy standing in for it in the whole scene, every
    sample taken, its slots holding `materials`; then `obj` is back and the copy hidden."""
    copy = scenes.preview_object(obj)
    bake, seconds = _bake_every_sample(copy, materials, spp)
    copy.hide_render = True
    obj.hide_render = False
    return bake, seconds


def touching_row(suzanne, first: str, second: str, spp: int) -> None:
    """Done-when (c) of issue 30: a 3 cm sphere of the second material pressed 2 mm into
    Suzanne's right cheek (beside her, on the floor's side of the key light), each object its
    own medium: each previewed with its own material (one precompute each, the other object an
    occluder), against one Cycles bake of the whole scene per object."""
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
    print(f"touching: Suzanne in {first} and a 3 cm ball in {second} pressed 2 mm into her cheek; occluders "
          f"{exports[0][1].occluders} and {exports[1][1].occluders}", flush=True)
    bakes = [_bake(o, [mat], spp) for o, mat in ((suzanne, mat1), (sphere, mat2))]
    for (o, m, mat), (scene, info), (bake, seconds) in zip(((suzanne, m1, mat1), (sphere, m2, mat2)), exports, bakes):
        _compare(f"touching, {o.name} in {mat.name}", scene, info, m, bake, seconds)
    suzanne.hide_render = False
    bpy.data.objects.remove(sphere)
    suzanne.data.materials.clear()


def eyes_row(suzanne, name: str, spp: int) -> None:
    """Done-when (d) of issue 30: Suzanne's eyes (the monkey's two smallest loose parts) in an
    opaque Principled BSDF (Base Color 0.05, no subsurface), the rest in the material: only the
    rest scatters and receives the preview, the eyes cast shadows. Compared over the vertices
    with no eye face (a vertex on the seam is baked as the mean of both materials)."""
    mesh = suzanne.data
    # Loose parts of the base mesh by union-find over its faces' vertices.
    parent = np.arange(len(mesh.vertices))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for poly in mesh.polygons:
        vs = list(poly.vertices)
        for v in vs[1:]:
            a, b = find(vs[0]), find(v)
            if a != b:
                parent[b] = a
    roots = np.array([find(i) for i in range(len(parent))])
    face_root = np.array([roots[poly.vertices[0]] for poly in mesh.polygons])
    parts, counts = np.unique(face_root, return_counts=True)
    eyes = parts[np.argsort(counts)[:2]]
    m = scenes.material(name)
    skin = cr.principled_material(m, f"{name} (Suzanne, eyes apart)")
    eye = bpy.data.materials.new("Eyes")
    if eye.node_tree is None:  # Blender < 5.0
        eye.use_nodes = True
    eye.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.05, 0.05, 0.05, 1.0)
    mesh.materials.clear()
    mesh.materials.append(skin)
    mesh.materials.append(eye)
    mesh.polygons.foreach_set("material_index", np.isin(face_root, eyes).astype(np.int32))
    suzanne.hide_render = False
    bpy.context.view_layer.update()
    scene, info = export.export_scene([suzanne], material=skin)
    bake, seconds = _bake(suzanne, [skin, eye], spp)
    # The exported vertices that no eye face touches, on the evaluated mesh.
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = suzanne.evaluated_get(depsgraph).to_mesh()
    seam = np.zeros(len(evaluated.vertices), bool)
    for poly in evaluated.polygons:
        if poly.material_index == 1:
            seam[list(poly.vertices)] = True
    suzanne.evaluated_get(depsgraph).to_mesh_clear()
    mask = ~seam[info.objects[0].vertices] if info.objects[0].vertices is not None else ~seam
    print(f"eyes apart: {int(np.isin(face_root, eyes).sum())} of {len(mesh.polygons)} base faces opaque; "
          f"occluders {info.occluders}", flush=True)
    _compare(f"eyes in an opaque material, Suzanne in {name}", scene, info, m, bake, seconds, mask)


if __name__ == "__main__":
    raise SystemExit(main())
