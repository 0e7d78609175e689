"""Scene export: the evaluated meshes (modifiers applied), lights and world of a Blender scene
as one `translucent.Scene`. The one exporter the add-on, the demo, scripts and tests share.

Units pass through as Blender's: positions in world space (scene units), sun Strength in W/m²,
point/spot/area Power in W, world Background colour x strength as radiance. Nothing here
changes user data: evaluated meshes are freed with `to_mesh_clear`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import bpy
import numpy as np

import translucent


@dataclass
class ObjectRange:
    """Where one object's vertices sit in the exported scene."""

    name: str
    start: int
    count: int


@dataclass
class ExportInfo:
    objects: list[ObjectRange] = field(default_factory=list)
    lights: list[str] = field(default_factory=list)
    skipped_lights: list[str] = field(default_factory=list)
    # Mesh objects left out because they do not carry the previewed material.
    skipped_objects: list[str] = field(default_factory=list)
    world: str = "black"


def evaluated_mesh_arrays(obj: bpy.types.Object, depsgraph) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World-space positions (N,3), triangles (M,3) and unit vertex normals (N,3) of the
    evaluated object (modifiers applied)."""
    eval_obj = obj.evaluated_get(depsgraph)
    mesh = eval_obj.to_mesh()
    try:
        mesh.calc_loop_triangles()
        n = len(mesh.vertices)
        co = np.empty(n * 3, dtype=np.float32)
        mesh.vertices.foreach_get("co", co)
        nrm = np.empty(n * 3, dtype=np.float32)
        mesh.vertex_normals.foreach_get("vector", nrm)
        tris = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int64)
        mesh.loop_triangles.foreach_get("vertices", tris)
    finally:
        eval_obj.to_mesh_clear()
    m = np.array(obj.matrix_world, dtype=np.float64)
    co = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
    # Normals transform by the inverse transpose.
    nrm = nrm.reshape(-1, 3) @ np.linalg.inv(m[:3, :3])
    lengths = np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm = np.where(lengths > 0, nrm / np.maximum(lengths, 1e-30), nrm)
    return co.astype(np.float32), tris.reshape(-1, 3), nrm.astype(np.float32)


def _direction(obj: bpy.types.Object) -> tuple[float, float, float]:
    """The object's -Z axis in world space: where Blender lights point."""
    m = np.array(obj.matrix_world, dtype=np.float64)[:3, :3]
    d = m @ np.array([0.0, 0.0, -1.0])
    return tuple((d / np.linalg.norm(d)).tolist())


def _axis(obj: bpy.types.Object, k: int) -> tuple[float, float, float]:
    m = np.array(obj.matrix_world, dtype=np.float64)[:3, :3]
    a = m[:, k]
    return tuple((a / np.linalg.norm(a)).tolist())


def add_lights(scene: translucent.Scene, bl_scene: bpy.types.Scene, info: ExportInfo) -> None:
    """Every visible light of `bl_scene`, in Blender's units; black or hidden lights skipped."""
    for obj in bl_scene.objects:
        if obj.type != "LIGHT":
            continue
        light = obj.data
        if obj.hide_render or light.energy <= 0.0 or max(light.color) <= 0.0:
            info.skipped_lights.append(obj.name)
            continue
        color = tuple(light.color)
        pos = tuple(obj.matrix_world.translation)
        if light.type == "SUN":
            scene.add_sun(_direction(obj), irradiance=light.energy, color=color)
        elif light.type == "POINT":
            scene.add_point_light(pos, power=light.energy, color=color)
        elif light.type == "SPOT":
            scene.add_spot_light(pos, _direction(obj), light.energy, light.spot_size, light.spot_blend, color=color)
        elif light.type == "AREA":
            sx = obj.matrix_world.to_scale()
            size_u = light.size * sx.x
            size_v = (light.size_y if light.shape in {"RECTANGLE", "ELLIPSE"} else light.size) * sx.y
            if light.shape in {"DISK", "ELLIPSE"}:
                # A rectangle of the same area stands in for the ellipse.
                k = math.sqrt(math.pi / 4.0)
                size_u, size_v = size_u * k, size_v * k
            scene.add_area_light(pos, _direction(obj), _axis(obj, 0), size_u, size_v, light.energy, color=color)
        else:
            info.skipped_lights.append(obj.name)
            continue
        info.lights.append(obj.name)


def set_world(scene: translucent.Scene, bl_scene: bpy.types.Scene, info: ExportInfo) -> None:
    """The world's Background: a uniform colour, or an Environment Texture image (radiance)."""
    world = bl_scene.world
    if world is None:
        return
    color, strength, image = tuple(world.color), 1.0, None
    tree = world.node_tree
    if tree is not None:
        bg = next((n for n in tree.nodes if n.type == "BACKGROUND"), None)
        if bg is not None:
            strength = bg.inputs["Strength"].default_value
            col = bg.inputs["Color"]
            color = tuple(col.default_value)[:3]
            if col.is_linked and col.links[0].from_node.type == "TEX_ENVIRONMENT":
                img = col.links[0].from_node.image
                if img is not None and img.size[0] > 0:
                    w, h = img.size
                    px = np.empty(w * h * 4, dtype=np.float32)
                    img.pixels.foreach_get(px)
                    # Blender stores rows bottom-up; translucent wants row 0 at the zenith.
                    image = px.reshape(h, w, 4)[::-1, :, :3].copy()
    if image is not None:
        scene.set_world(image=image, strength=strength)
        info.world = "environment"
    elif max(color) * strength > 0.0:
        scene.set_world(color=color, strength=strength)
        info.world = "uniform"


def export_scene(
    objects: list[bpy.types.Object], depsgraph=None, bl_scene: bpy.types.Scene | None = None
) -> tuple[translucent.Scene, ExportInfo]:
    """One `translucent.Scene` from `objects` (their evaluated meshes merged) with the lights and
    world of `bl_scene`. `info.objects` says which vertex range belongs to which object."""
    bl_scene = bl_scene or bpy.context.scene
    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    info = ExportInfo()
    parts_p, parts_t, parts_n = [], [], []
    offset = 0
    for obj in objects:
        if obj.type != "MESH":
            raise ValueError(f"{obj.name} is a {obj.type}, not a mesh")
        p, t, n = evaluated_mesh_arrays(obj, depsgraph)
        parts_p.append(p)
        parts_t.append(t + offset)
        parts_n.append(n)
        info.objects.append(ObjectRange(obj.name, offset, len(p)))
        offset += len(p)
    if not parts_p:
        raise ValueError("no objects to export")
    scene = translucent.Scene(np.concatenate(parts_p), np.concatenate(parts_t), np.concatenate(parts_n))
    add_lights(scene, bl_scene, info)
    set_world(scene, bl_scene, info)
    return scene, info
