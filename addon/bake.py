"""Cycles' emission pass baked per vertex or per face corner of temporary meshes: how the add-on
lets Blender evaluate a node tree (a textured Base Color, an emitter's textured or mixed
emission) instead of re-implementing nodes. The meshes are the caller's temporary copies; the
objects and the scene holding them here are made for the bake and removed again whatever
happens. The user's objects, meshes, materials and images are only read."""

from __future__ import annotations

import contextlib
import hashlib

import bpy
import numpy as np

BAKE_SCENE = "Translucent bake"
ATTRIBUTE = "translucent_bake"
# True while a bake runs (`baking`): the add-on's depsgraph handlers ignore the updates the
# bake's own temporary data causes.
BAKING = False
_DEPTH = 0


@contextlib.contextmanager
def baking():
    """`BAKING` for the block, its temporary copies included (nested blocks keep it on until
    the outermost ends)."""
    global BAKING, _DEPTH
    _DEPTH += 1
    BAKING = True
    try:
        yield
    finally:
        _DEPTH -= 1
        BAKING = _DEPTH > 0


def emission(parts: list[tuple[bpy.types.Mesh, object, list]], domain: str = "POINT") -> list[np.ndarray]:
    """The emission pass, linear RGB, of each (mesh, world matrix, object-linked slots) of
    `parts` as Cycles renders it (`bpy.ops.object.bake(type="EMIT", target="VERTEX_COLORS")`,
    1 sample): an (N, 3) float32 array per mesh, per vertex (`domain` "POINT") or per face
    corner in loop order ("CORNER"). Each mesh is placed at its matrix, so Object and Generated
    coordinates agree with the object's; the third item lists (slot index, material) pairs the
    object links at object level. Raises ValueError when the bake fails (the message says why)."""
    with baking():
        return _emission(parts, domain)


def _emission(parts, domain: str) -> list[np.ndarray]:
    made, scene = [], None
    try:
        scene = bpy.data.scenes.new(BAKE_SCENE)
        scene.render.engine = "CYCLES"
        scene.cycles.device = "CPU"
        scene.cycles.samples = 1
        scene.cycles.use_denoising = False
        scene.cycles.use_adaptive_sampling = False
        for mesh, matrix, object_slots in parts:
            attr = mesh.color_attributes.new(ATTRIBUTE, "FLOAT_COLOR", domain)
            mesh.color_attributes.active_color = attr
            tmp = bpy.data.objects.new(f"{mesh.name} (bake)", mesh)
            made.append(tmp)
            tmp.matrix_world = matrix
            for k, mat in object_slots:
                if k < len(tmp.material_slots):
                    tmp.material_slots[k].link = "OBJECT"
                    tmp.material_slots[k].material = mat
            scene.collection.objects.link(tmp)
        layer = scene.view_layers[0]
        with bpy.context.temp_override(scene=scene, view_layer=layer, active_object=made[0], object=made[0],
                                       selected_objects=made, selected_editable_objects=made):
            for tmp in made:
                tmp.select_set(True, view_layer=layer)
            layer.objects.active = made[0]
            result = bpy.ops.object.bake(type="EMIT", target="VERTEX_COLORS")
        if result != {"FINISHED"}:
            raise ValueError(f"Cycles' emission bake returned {result}")
        out = []
        for mesh, _, _ in parts:
            data = mesh.color_attributes[ATTRIBUTE].data
            px = np.empty(len(data) * 4, np.float32)
            data.foreach_get("color", px)
            out.append(px.reshape(-1, 4)[:, :3].copy())
        return out
    except RuntimeError as e:
        raise ValueError(f"Cycles' emission bake failed: {e}") from e
    finally:
        for tmp in made:
            bpy.data.objects.remove(tmp)
        if scene is not None:
            bpy.data.scenes.remove(scene)


def upstream(start: list) -> list:
    """The nodes `start` and every node they read from, directly or through other nodes
    (groups' insides are in their own trees: a group node counts by its inputs and its tree's
    name)."""
    seen, stack = {}, list(start)
    while stack:
        n = stack.pop()
        if n.name in seen:
            continue
        seen[n.name] = n
        stack.extend(link.from_node for sock in n.inputs for link in sock.links)
    return list(seen.values())


def nodes_key(nodes: list) -> str:
    """What a bake reading `nodes` depends on, as a digest: their inputs' values, their
    properties and the links between them, and the state of the images they read (name, size,
    file, dirty flag). Equal keys, the same bake."""
    parts = []
    names = {n.name for n in nodes}
    for node in nodes:
        parts.append((node.name, node.bl_idname))
        for sock in node.inputs:
            v = getattr(sock, "default_value", None)
            parts.append((sock.identifier, tuple(v) if hasattr(v, "__len__") and not isinstance(v, str) else v))
            parts.extend((link.from_node.name, link.from_socket.identifier, sock.identifier) for link in sock.links)
        for prop in node.bl_rna.properties:
            if prop.identifier in {"rna_type", "location", "width", "height", "select", "dimensions",
                                   "location_absolute", "warning_propagation", "name", "label"}:
                continue
            try:
                value = getattr(node, prop.identifier)
            except AttributeError:
                continue
            if isinstance(value, bpy.types.Image):
                # The image's pixels: reloaded, replaced or painted (the dirty flag; strokes after
                # the first come through the depsgraph, `edits.follow_principled`).
                parts.append((value.name, tuple(value.size), value.is_dirty, value.filepath))
            elif isinstance(value, bpy.types.ID):
                parts.append((prop.identifier, value.name))
            elif isinstance(value, (int, float, str, bool)):
                parts.append((prop.identifier, value))
    parts.append(sorted(names))
    return hashlib.blake2b(repr(parts).encode(), digest_size=16).hexdigest()
