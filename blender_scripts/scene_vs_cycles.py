"""The preview in an artist's scene against Cycles (issue 30): the demo's Suzanne standing on a
floor, a box between her and the key light casting its shadow across her, compared with a
Cycles vertex bake of the whole scene (every sample taken). Rows split by what each part adds:
the lone object as the preview saw it before issue 30 (no other object), the other objects as
shadows only (black), and as shadows that send light back (their own albedo); then the same
scene with a textured Base Color (a checker), read per vertex and as the socket's value alone.

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

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import bpy  # noqa: E402

import translucent  # noqa: E402
from addon import export  # noqa: E402
from blender_scripts.lib import cycles_reference as cr  # noqa: E402
from blender_scripts.lib import scenes  # noqa: E402
from blender_scripts.lib.machine import describe as machine  # noqa: E402
from blender_scripts.lib.metrics import rel  # noqa: E402

FLOOR_COLOUR = (0.6, 0.55, 0.5)


def props(suzanne: bpy.types.Object) -> list[bpy.types.Object]:
    """A 1 m floor 1 mm under Suzanne (Principled BSDF, FLOOR_COLOUR) and a 3 cm box a third
    of the way to the key light, beside the line to it (no material: Cycles' grey 0.8)."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    p, _, _ = export.evaluated_mesh_arrays(suzanne, depsgraph)
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(0.0, 0.0, float(p[:, 2].min()) - 0.001))
    floor = bpy.context.active_object
    floor.name = "Floor"
    mat = bpy.data.materials.new("Floor")
    if mat.node_tree is None:  # Blender < 5.0
        mat.use_nodes = True
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (*FLOOR_COLOUR, 1.0)
    floor.data.materials.append(mat)
    bpy.ops.mesh.primitive_cube_add(size=0.03, location=(0.062, -0.077, 0.07))
    box = bpy.context.active_object
    box.name = "Box"
    return [floor, box]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--materials", nargs="+", default=["marble", "skin1"])
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--texture", action=argparse.BooleanOptionalAction, default=True,
                    help="also the scene with a textured Base Color (issue 30, point 2)")
    args = ap.parse_args(argv)
    print(f"machine: {machine()}")
    obj, _ = scenes.build_scene("suzanne")
    others = props(obj)
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
    floor_input.default_value = (*FLOOR_COLOUR, 1.0)
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
        for label, s in variants.items():
            t0 = time.perf_counter()
            prt = translucent.Prt(s, m, backend="cpu", single_scattering=False)
            seconds = time.perf_counter() - t0
            preview = prt.radiance(m)
            est = 100 * max(prt.last_eval["error_estimate"])
            print(f"{name}, {label}: {100 * rel(preview, bake, w):.2f} % from Cycles (estimate {est:.2f} %), "
                  f"precompute {seconds:.1f} s; bake {bake_s:.0f} s", flush=True)
        if args.texture:
            textured_row(name, m, bake_obj, scene, w, args.spp)
    return 0


def textured_row(name: str, m, bake_obj, scene, w, spp: int) -> None:
    """The same scene with the material's Principled BSDF given a textured Base Color (a
    Checker Texture: its own colour and half of it, like freckles): the preview reading it per
    vertex (`Prt.radiance(base_color=...)`, the add-on's Cycles bake of the Base Color) and the
    socket's own value shown uniformly (before issue 30), against a Cycles bake of the textured
    material."""
    from addon import textures
    from translucent import cycles

    mat = cr.principled_material(m, f"{name} textured")
    node = mat.node_tree.nodes["Principled BSDF"]
    colour = tuple(node.inputs["Base Color"].default_value)
    checker = mat.node_tree.nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 6.0
    checker.inputs["Color1"].default_value = colour
    checker.inputs["Color2"].default_value = (*(0.5 * c for c in colour[:3]), 1.0)
    mat.node_tree.links.new(checker.outputs["Color"], node.inputs["Base Color"])
    bake_obj.data.materials.clear()
    bake_obj.data.materials.append(mat)
    scene_bl = cr.use_cycles(spp, 0)
    scene_bl.cycles.use_adaptive_sampling = False
    t0 = time.perf_counter()
    bake = cr.bake_diffuse_vertex_colors(bake_obj, {"DIRECT", "INDIRECT", "COLOR"})
    bake_s = time.perf_counter() - t0
    baked, texture_s = textures.bake_base_color(mat, [bake_obj])
    colours = baked[bake_obj.name]
    inputs = cycles.read_principled(node)
    t0 = time.perf_counter()
    prt = translucent.Prt(scene, textures.representatives(inputs, colours), backend="cpu", single_scattering=False)
    seconds = time.perf_counter() - t0
    preview = prt.radiance(inputs.material(), base_color=colours)
    est = 100 * max(prt.last_eval["error_estimate"])
    print(f"{name}, textured Base Color read per vertex: {100 * rel(preview, bake, w):.2f} % from Cycles "
          f"(estimate {est:.2f} %), precompute {seconds:.1f} s, the Base Color's bake {1000 * texture_s:.0f} ms; "
          f"bake {bake_s:.0f} s", flush=True)
    uniform = translucent.Prt(scene, inputs.material(), backend="cpu", single_scattering=False).radiance(inputs.material())
    print(f"{name}, textured, the socket's value shown uniformly (before issue 30): "
          f"{100 * rel(uniform, bake, w):.2f} % from Cycles", flush=True)
    bake_obj.data.materials.clear()


if __name__ == "__main__":
    raise SystemExit(main())
