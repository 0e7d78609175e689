"""Scene export: the evaluated meshes (modifiers applied), lights and world of a Blender scene
as one `translucent.Scene`. The one exporter the add-on, the demo, scripts and tests share.

Units pass through as Blender's: positions in world space (scene units), sun Strength in W/m²,
point/spot/area Power in W, world Background colour x strength as radiance. Nothing here
changes user data: evaluated meshes are freed with `to_mesh_clear`.
"""

from __future__ import annotations

import hashlib
import math
import time
from dataclasses import dataclass, field

import bpy
import numpy as np

import translucent
from translucent import cycles

from . import bake, emission, linking


@dataclass
class ObjectRange:
    """Where one object's vertices sit in the exported scene."""

    name: str
    start: int
    count: int
    # What the exported geometry was (counts, faces' material slots and world-space positions,
    # hashed): the add-on compares it to notice a deformation, and to tell it from its own
    # colour writes.
    geometry_key: str = ""
    # Which of the evaluated mesh's vertices were exported, in order (those of the faces of
    # the previewed material; None: all of them).
    vertices: np.ndarray | None = None
    # The evaluated mesh's vertex count.
    evaluated_count: int = 0
    # Exported with `others_scatter`: per exported vertex, (count, 3), the diffuse albedo of the
    # other material whose faces alone touch it (they scatter as that colour and are not
    # previewed); NaN rows for the previewed vertices. None: every exported vertex is previewed.
    others: np.ndarray | None = None
    # With `others`: per exported vertex, the material slot whose material's albedo it takes (-1
    # for the previewed vertices), so a change of that material is read again (`others_now`).
    other_slots: np.ndarray | None = None


@dataclass
class MeshLight:
    """An emitter's faces as one mesh light (`translucent.Scene.add_mesh_light`): world-space
    positions, triangles and their radiance (one RGB, or per triangle corner, (T, 3, 3), where
    Cycles' emission pass was baked); `visible_shadow` false for an object hidden from shadow
    rays; `whole` where it is all the object emits."""
    obj: object
    positions: np.ndarray
    triangles: np.ndarray
    radiance: tuple = (1.0, 1.0, 1.0)
    corners: np.ndarray | None = None
    visible_shadow: bool = True
    whole: bool = True
    # Where only some faces may emit (a previewed object's faces of other materials): those.
    faces: np.ndarray | None = None
    # Waiting for its bake: the faces of one constant radiance, the lights kept if it fails.
    fallback: list = field(default_factory=list)
    # An instance's world matrix (a copy: the depsgraph's instances last only while iterated),
    # where the bake's copy of `obj`'s evaluated mesh is placed; None: `obj`'s own.
    matrix: object = None


@dataclass
class ExportInfo:
    objects: list[ObjectRange] = field(default_factory=list)
    lights: list[str] = field(default_factory=list)
    skipped_lights: list[str] = field(default_factory=list)
    # Objects of the scene whose material emits light (`translucent.cycles.emits`): they light
    # it in Cycles, and are not lights here (shadows and bounce only).
    emitters: list[str] = field(default_factory=list)
    # Emissive rectangles found among the occluders (`_emissive_rectangle`), made area lights
    # by `add_lights`: (object, (centre, normal, axis_u, size_u, size_v, radiance)).
    emissive_rectangles: list = field(default_factory=list)
    # Other emitters' faces (`_add_emitter`), made mesh lights by `add_lights`.
    emissive_meshes: list[MeshLight] = field(default_factory=list)
    # What was read of the emitters' textured or mixed emission, for the panel, and the
    # emitters whose emission is still to be baked (`_bake_emitters`).
    emission: list[str] = field(default_factory=list)
    to_bake: list[MeshLight] = field(default_factory=list)
    # Lights whose light linking lights none of the exported objects (`linking.follow`), and
    # the lines saying what of the lights' linking is not followed.
    unlinked_lights: list[str] = field(default_factory=list)
    linking: list[str] = field(default_factory=list)
    # Each occluder's label ("Box", "Box [Paint]", "Head [other materials]") -> its object's name.
    occluder_objects: dict[str, str] = field(default_factory=dict)
    # Mesh objects left out because they do not carry the previewed material.
    skipped_objects: list[str] = field(default_factory=list)
    # Other objects exported as occluders (they shadow the previewed ones; issue 30), and the
    # faces of other materials of the previewed objects ("Head [other materials]").
    occluders: list[str] = field(default_factory=list)
    # Objects that hold the material in a slot but on none of their faces: left out.
    without_faces: list[str] = field(default_factory=list)
    # "occluder NAME" -> its geometry key(s) at the export (`occluder_keys`): the add-on
    # compares them to notice a prop moved, deformed, added, hidden or removed.
    occluder_keys: dict[str, str] = field(default_factory=dict)
    world: str = "black"
    # The exported vertices' world-space positions, (N, 3) float32: what a hierarchy of the same
    # topology is updated to.
    positions: np.ndarray | None = None


def evaluated_mesh_arrays(obj: bpy.types.Object, depsgraph) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World-space positions (N,3), triangles (M,3) and unit vertex normals (N,3) of the
    evaluated object (modifiers applied)."""
    p, t, n, _, _ = _evaluate(obj, depsgraph, triangles=True)
    return p, t, n


def object_geometry_key(obj: bpy.types.Object, depsgraph=None) -> str:
    """The `ObjectRange.geometry_key` of the object as it evaluates now (modifiers, armature,
    shape keys, edit mode), without its triangles and normals: about 10 ms at 100k vertices."""
    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    return _evaluate(obj, depsgraph, triangles=False)[3]


def _evaluate(obj: bpy.types.Object, depsgraph, triangles: bool, instance=None):
    """The one place the add-on evaluates a mesh: world-space positions, then (if `triangles`)
    triangles, unit normals and each triangle's material slot, and the geometry key (vertex,
    corner and face counts, the faces' material slots' digest and the positions' digest: equal
    keys, same exported mesh up to a re-triangulation; `same_topology` compares the first
    four). `instance`: a depsgraph object instance whose evaluated object and matrix are used
    instead."""
    eval_obj = obj.evaluated_get(depsgraph) if instance is None else instance.object
    mesh = eval_obj.to_mesh()
    tris = nrm = slots = None
    try:
        n = len(mesh.vertices)
        co = np.empty(n * 3, dtype=np.float32)
        # The position attribute reads as one block (vertices' "co" goes item by item).
        mesh.attributes["position"].data.foreach_get("vector", co)
        face_slots = np.empty(len(mesh.polygons), dtype=np.int32)
        mesh.polygons.foreach_get("material_index", face_slots)
        counts = (f"{n}:{len(mesh.loops)}:{len(mesh.polygons)}:"
                  f"{hashlib.blake2b(face_slots.tobytes(), digest_size=8).hexdigest()}")
        if triangles:
            mesh.calc_loop_triangles()
            nrm = np.empty(n * 3, dtype=np.float32)
            mesh.vertex_normals.foreach_get("vector", nrm)
            tris = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int64)
            mesh.loop_triangles.foreach_get("vertices", tris)
            tris = tris.reshape(-1, 3)
            slots = np.empty(len(mesh.loop_triangles), dtype=np.int32)
            mesh.loop_triangles.foreach_get("material_index", slots)
    finally:
        eval_obj.to_mesh_clear()
    m = np.array(obj.matrix_world if instance is None else instance.matrix_world, dtype=np.float64)
    co = (co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]).astype(np.float32)
    key = f"{counts}:{hashlib.blake2b(co.tobytes(), digest_size=16).hexdigest()}"
    if tris is not None and np.linalg.det(m[:3, :3]) < 0.0:
        # A mirroring transform (a negative scale) turns the winding inward while Blender keeps
        # the shading outward: the exported triangles turn back so they stay outward too.
        tris = tris[:, ::-1].copy()
    if nrm is not None:
        # Normals transform by the inverse transpose.
        nrm = nrm.reshape(-1, 3) @ np.linalg.inv(m[:3, :3])
        lengths = np.linalg.norm(nrm, axis=1, keepdims=True)
        nrm = np.where(lengths > 0, nrm / np.maximum(lengths, 1e-30), nrm).astype(np.float32)
    return co, tris, nrm, key, slots


def evaluated_copy(obj: bpy.types.Object, depsgraph) -> bpy.types.Mesh:
    """A new mesh data-block holding `obj`'s evaluated mesh with every data layer (UV maps,
    colour attributes), in object space: for a bake on a temporary copy (`textures`,
    `emission`). The caller removes it. The other place the add-on evaluates a mesh
    (`_evaluate` is the first)."""
    return bpy.data.meshes.new_from_object(obj.evaluated_get(depsgraph), preserve_all_data_layers=True,
                                           depsgraph=depsgraph)


def same_topology(key: str, other: str) -> bool:
    """Whether two geometry keys have the same vertex, corner and face counts and the same
    faces' material slots (only the positions may differ: a deformation)."""
    return key.split(":")[:4] == other.split(":")[:4]


def lighting_keys(bl_scene: bpy.types.Scene) -> dict[str, str]:
    """What each light, and the world, hand to the export (by name; "world" for the world),
    as strings to compare: no mesh is evaluated, so this is cheap enough for every update."""
    keys = {}
    for o in bl_scene.objects:
        if o.type != "LIGHT":
            continue
        d = o.data
        keys[f"light {o.name}"] = repr((
            tuple(round(x, 9) for row in o.matrix_world for x in row), d.type, d.energy, tuple(d.color),
            getattr(d, "spot_size", 0), getattr(d, "spot_blend", 0), getattr(d, "size", 0),
            getattr(d, "size_y", 0), getattr(d, "shape", ""), o.hide_render, linking.key(o)))
    w = bl_scene.world
    if w is not None:
        parts = [tuple(w.color)]
        if w.node_tree is not None:
            for n in w.node_tree.nodes:
                parts.append(n.name)
                if n.type == "TEX_ENVIRONMENT":
                    parts.append(n.image.name if n.image is not None else None)
                for i in n.inputs:
                    if hasattr(i, "default_value"):
                        v = i.default_value
                        parts.append(tuple(v) if hasattr(v, "__len__") else v)
                    parts.append(i.is_linked)
        keys["world"] = repr(parts)
    return keys


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
    """Every visible light of `bl_scene`, in Blender's units, with its light and shadow linking
    (`linking.link`); black or hidden lights skipped, and lights whose light linking lights none
    of the exported objects left out (`linking.follow`: `info.linking` says so, and what of their
    linking is not followed)."""
    previewed = [r.name for r in info.objects]
    occluders = sorted(k.removeprefix("occluder ") for k in info.occluder_keys)
    added = 0  # the lights added so far: the next one's place, for the linking

    def link(obj, count: int) -> None:
        # The `count` lights just added for `obj`.
        linking.link(scene, range(added - count, added), obj, previewed, info.occluder_objects)

    for obj in bl_scene.objects:
        if obj.type != "LIGHT":
            continue
        light = obj.data
        if obj.hide_render or light.energy <= 0.0 or max(light.color) <= 0.0:
            info.skipped_lights.append(obj.name)
            continue
        kept, lines = linking.follow(obj, previewed, occluders)
        info.linking.extend(lines)
        if not kept:
            info.unlinked_lights.append(obj.name)
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
        added += 1
        link(obj, 1)
        info.lights.append(obj.name)
    # Emissive rectangles: a Lambertian rectangle of radiance L on each side is an area light of
    # power pi A L (the core's area light has radiance P / (pi A), as Cycles' has), each side's
    # lifted off the rectangle by a thousandth of its size, or the rectangle (an occluder too)
    # would shadow its own light: 0.4 of it reached a ball 15 cm below.
    for obj, (centre, normal, axis_u, size_u, size_v, radiance) in info.emissive_rectangles:
        kept, lines = linking.follow(obj, previewed, occluders)
        info.linking.extend(lines)
        if obj.name in info.emitters:
            info.emitters.remove(obj.name)
        if not kept:
            info.unlinked_lights.append(obj.name)
            continue
        k = max(radiance)
        lift = 1e-3 * max(size_u, size_v)
        for side in (normal, -normal):
            scene.add_area_light(tuple(centre + lift * side), tuple(side), tuple(axis_u), size_u, size_v,
                                 math.pi * size_u * size_v * k, color=tuple(c / k for c in radiance))
        added += 2
        link(obj, 2)
        info.lights.append(f"{obj.name} (emissive rectangle)")
    # Other emissive meshes (a sphere, a tube, a neon sign): a mesh light emitting from both
    # sides of their faces, as Cycles' mesh emission does, of one radiance per material or of
    # Cycles' own emission pass per corner; being occluders too, they hide their own far side,
    # unless hidden from shadow rays.
    for m in info.emissive_meshes:
        kept, lines = linking.follow(m.obj, previewed, occluders)
        info.linking.extend(lines)
        if m.whole and m.obj.name in info.emitters:
            info.emitters.remove(m.obj.name)
        if not kept:
            info.unlinked_lights.append(m.obj.name)
            continue
        k = max(m.radiance)
        scene.add_mesh_light(m.positions, m.triangles, k, color=tuple(c / k for c in m.radiance),
                             corner_colors=m.corners, visible_shadow=m.visible_shadow)
        added += 1
        link(m.obj, 1)
        how = ", textured" if m.corners is not None else ""
        how += "" if m.visible_shadow else ", hidden from shadow rays"
        info.lights.append(f"{m.obj.name} (emissive mesh{how})")


# Object types Cycles renders as surfaces: their evaluated mesh casts the shadow.
_SURFACES = {"MESH", "CURVE", "FONT", "META", "SURFACE"}


def _occluder_instances(depsgraph, previewed: set):
    """The depsgraph's instances that Cycles' shadow rays see (visible to shadow rays, not
    hidden from render; meshes, curves, text, metaballs, instances and geometry-nodes output),
    the previewed objects themselves (not their instanced copies) left out: (original, instance)
    pairs, valid while the iteration runs."""
    for inst in depsgraph.object_instances:
        obj = inst.object
        original = obj.original
        if obj.type not in _SURFACES or (not inst.is_instance and original.name in previewed):
            continue
        if original.hide_render or not getattr(original, "visible_shadow", True):
            continue
        yield original, inst


def slot_materials(obj, instance=None) -> list:
    """The material in each of `obj`'s slots as Cycles renders it (None for an empty slot): an
    instance's read from its evaluated object while the depsgraph is iterated (geometry nodes
    give their instances materials of their own, the Set Material node's), as the user's
    data-blocks."""
    slots = obj.material_slots if instance is None else instance.object.material_slots
    return [None if sl.material is None else sl.material.original for sl in slots]


def _add_key(keys: dict, obj, key: str, materials: list, kind: str = "occluder") -> None:
    # The geometry and what the object sends back (its slots' albedo: a colour edit relights);
    # an object instanced several times: its instances' keys in the depsgraph's order.
    albedo = [cycles.diffuse_albedo(m) for m in materials] or [cycles.DEFAULT_SURFACE]
    # What it emits: one radiance, or the digest of the nodes a textured or mixed one reads.
    keys[f"{kind} {obj.name}"] = keys.get(f"{kind} {obj.name}", "") + f"{key}:{albedo!r}:{_glow_key(materials)};"


def occluder_keys(depsgraph, previewed: set) -> dict[str, str]:
    """What `add_occluders` would export now, as `ExportInfo.occluder_keys` holds it: each
    occluder's geometry key (world-space positions hashed, no triangles): about 10 ms per 100k
    vertices, so the follow check computes it only when something besides the previewed objects
    changed."""
    keys: dict[str, str] = {}
    for original, inst in _occluder_instances(depsgraph, previewed):
        try:
            _add_key(keys, original, _evaluate(original, depsgraph, triangles=False, instance=inst)[3],
                     slot_materials(original, inst))
        except RuntimeError:
            continue
    for obj in _shadowless_emitters(depsgraph.scene, previewed):
        try:
            _add_key(keys, obj, _evaluate(obj, depsgraph, triangles=False)[3], slot_materials(obj), kind="emitter")
        except RuntimeError:
            continue
    for name in previewed:
        obj = bpy.data.objects.get(name)
        if obj is not None and any(cycles.emits(s.material) for s in obj.material_slots):
            keys[f"glow {name}"] = _glow_key(slot_materials(obj))
    return keys


def _glow_key(materials: list) -> str:
    """What each of an object's slots' `materials` emits, as a string: one radiance, the digest
    of the nodes a textured or mixed emission reads (`emission.key`), or None. Part of an
    occluder's or emitter's key, and a previewed object's own ("glow NAME"): a change rebuilds
    the preview."""
    return repr([cycles.emission(m) or (emission.key(m) if cycles.emits(m) else None) for m in materials])


def _shadowless_emitters(bl_scene, previewed: set):
    """The objects Cycles renders as surfaces that emit light and are hidden from shadow rays
    (not hidden from render, not previewed): they light the scene and shadow nothing."""
    for obj in bl_scene.objects:
        if (obj.type in _SURFACES and not obj.hide_render and not getattr(obj, "visible_shadow", True)
                and obj.name not in previewed and any(cycles.emits(sl.material) for sl in obj.material_slots)):
            yield obj


def _add_parts(scene: translucent.Scene, obj, name: str, co, tris, slots, info: ExportInfo, materials: list) -> None:
    """`tris` of `obj` as occluders, one per material slot they use, each sending light back by
    its material's diffuse albedo (`translucent.cycles.diffuse_albedo`; `materials`: each slot's,
    `slot_materials`): named `name` where they use one slot, "OBJECT [Material]" for each where
    several."""
    used = np.unique(slots)
    for k in used:
        mat = materials[k] if k < len(materials) else None
        if cycles.emits(mat) and obj.name not in info.emitters:
            info.emitters.append(obj.name)
        label = name if len(used) == 1 else f"{obj.name} [{mat.name if mat is not None else 'no material'}]"
        scene.add_occluder(co, tris[slots == k], name=label, albedo=cycles.diffuse_albedo(mat))
        info.occluders.append(label)
        info.occluder_objects[label] = obj.name


def add_occluders(scene: translucent.Scene, depsgraph, previewed: set, info: ExportInfo) -> None:
    """Every other object Cycles' shadow rays see (`_occluder_instances`) as an occluder of
    `scene`, in world space, sending light back by its materials' albedo (`_add_parts`), its key
    kept in `info.occluder_keys`. Evaluated meshes are freed again."""
    for original, inst in _occluder_instances(depsgraph, previewed):
        try:
            co, tris, _, key, slots = _evaluate(original, depsgraph, triangles=True, instance=inst)
        except RuntimeError:
            continue
        materials = slot_materials(original, inst)
        _add_key(info.occluder_keys, original, key, materials)
        if len(co) == 0 or len(tris) == 0:
            continue
        _add_parts(scene, original, original.name, co, tris, slots, info, materials)
        _add_emitter(original, co, tris, slots, info, materials, instance=inst)


def _add_emitter(obj, co, tris, slots, info: ExportInfo, materials: list, instance=None, visible_shadow: bool = True,
                 faces: np.ndarray | None = None) -> None:
    """The light `obj`'s faces (`tris` of world-space `co`, their material `slots`; only those
    `faces` selects where given) emit, kept in `info` for `add_lights`: an emissive rectangle
    as two area lights; faces of one constant radiance per material as mesh lights; a textured
    or mixed emission (`cycles.emits` without one `cycles.emission`) left for `_bake_emitters`
    (after the depsgraph's instances are iterated: a bake adds data); an instance's baked on a
    copy of its object's evaluated mesh placed at the instance's matrix."""
    rectangle = _emissive_rectangle(co, tris, slots, materials) if faces is None else None
    if rectangle is not None:
        info.emissive_rectangles.append((obj, rectangle))
        return
    parts, whole = _emissive_parts(tris if faces is None else tris[faces], slots if faces is None else slots[faces],
                                   materials)
    constant = [MeshLight(obj, co, part, radiance, visible_shadow=visible_shadow, whole=whole) for part, radiance in parts]
    if not whole:
        matrix = instance.matrix_world.copy() if instance is not None and instance.is_instance else None
        info.to_bake.append(MeshLight(obj, co, tris, visible_shadow=visible_shadow, faces=faces, fallback=constant,
                                      matrix=matrix))
        return
    info.emissive_meshes.extend(constant)


def _bake_emitters(info: ExportInfo) -> None:
    """Each emitter of a textured or mixed emission in `info.to_bake` as one mesh light of
    Cycles' emission pass at every face corner (`emission.corner_radiance` on a temporary copy
    of its evaluated mesh); where the bake fails, its faces of one constant radiance alone,
    the object named in `info.emitters`. An instance's emission is its object's mesh baked at
    the instance's place (Object and Generated coordinates as the instance's own); an instance
    of geometry no object holds (a geometry-nodes mesh) has no such copy and keeps its constant
    faces, named."""
    for m in info.to_bake:
        t0 = time.perf_counter()
        depsgraph = bpy.context.evaluated_depsgraph_get()
        try:
            with bake.baking():  # the copy's updates are the bake's own
                mesh = evaluated_copy(m.obj, depsgraph)
                try:
                    matrix = m.obj.matrix_world if m.matrix is None else m.matrix
                    m.corners = emission.corner_radiance(m.obj, mesh, matrix, m.triangles)
                finally:
                    bpy.data.meshes.remove(mesh)
        except ValueError as e:
            what = "an instance's emission" if m.matrix is not None else "its emission"
            line = f"{m.obj.name}: {what} was not read ({e})"
            if line not in info.emission:  # once for all its instances
                info.emission.append(line)
            info.emissive_meshes.extend(m.fallback)
            continue
        glowing = m.corners.reshape(len(m.triangles), -1).max(axis=1) > 0.0
        if m.faces is not None:
            glowing &= m.faces
        if glowing.any():
            m.triangles, m.corners = m.triangles[glowing], m.corners[glowing]
            info.emissive_meshes.append(m)
        elif m.obj.name in info.emitters:
            info.emitters.remove(m.obj.name)  # black wherever Cycles looked: no light
        info.emission.append(f"{m.obj.name}: emission read by Cycles at {3 * len(glowing):,} face corners "
                             f"in {1000 * (time.perf_counter() - t0):.0f} ms")
    info.to_bake = []


def _emissive_parts(tris, slots, materials: list):
    """The faces `tris` (their material `slots`, each slot's of `materials`) whose material
    emits one constant radiance (`translucent.cycles.emission`), as a list of (triangles,
    radiance) per such material, and whether those are all it emits from (no textured or mixed
    emission)."""
    parts, whole = [], True
    for k in np.unique(slots):
        mat = materials[k] if k < len(materials) else None
        radiance = cycles.emission(mat)
        if radiance is not None:
            parts.append((tris[slots == k], radiance))
        elif cycles.emits(mat):
            whole = False
    return parts, whole


def _emissive_rectangle(co, tris, slots, materials: list):
    """An emissive rectangle (a softbox, a light panel): faces `tris` of `co`, all of one slot
    whose material (of `materials`) emits a constant radiance (`translucent.cycles.emission`),
    on four corners that make a rectangle; as (centre, unit normal, unit axis_u, size_u,
    size_v, radiance), else None."""
    used = np.unique(slots)
    if len(used) != 1 or used[0] >= len(materials):
        return None
    radiance = cycles.emission(materials[int(used[0])])
    corners = np.unique(tris)
    if radiance is None or len(corners) != 4:
        return None
    p = co[corners].astype(np.float64)
    far = int(np.argmax(np.linalg.norm(p - p[0], axis=1)))  # the corner across from p[0]
    side = [k for k in (1, 2, 3) if k != far]
    e1, e2 = p[side[0]] - p[0], p[side[1]] - p[0]
    l1, l2 = np.linalg.norm(e1), np.linalg.norm(e2)
    diagonal = np.linalg.norm(p[far] - p[0])
    if min(l1, l2) <= 0.0 or abs(e1 @ e2) > 1e-4 * l1 * l2 or np.linalg.norm(p[0] + e1 + e2 - p[far]) > 1e-5 * diagonal:
        return None
    normal = np.cross(e1, e2)
    return (p.mean(axis=0), normal / np.linalg.norm(normal), e1 / l1, float(l1), float(l2), radiance)


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


def material_slots(obj: bpy.types.Object, material: bpy.types.Material) -> set[int]:
    """The indices of `obj`'s material slots that hold `material`."""
    return {i for i, slot in enumerate(obj.material_slots) if slot.material == material}


def other_slots(tris: np.ndarray, slots: np.ndarray, mine: np.ndarray, count: int) -> np.ndarray:
    """Per vertex of an evaluated mesh (`count`), the material slot of the other material whose
    faces (`~mine`) alone touch it, -1 for the vertices of the previewed faces (`mine`)."""
    out = np.full(count, -1, dtype=np.int32)
    for k in np.unique(slots[~mine]):
        out[tris[(slots == k) & ~mine].ravel()] = k
    out[tris[mine].ravel()] = -1
    return out


def other_materials(obj: bpy.types.Object, slots: np.ndarray) -> dict[int, bpy.types.Material | None]:
    """The material now in each slot that `slots` (`other_slots`) names, by slot (None: an empty
    slot, or one the object no longer has)."""
    return {int(k): obj.material_slots[k].material if k < len(obj.material_slots) else None
            for k in np.unique(slots[slots >= 0])}


def others_now(obj: bpy.types.Object, slots: np.ndarray) -> np.ndarray:
    """Per vertex, the diffuse albedo (`translucent.cycles.diffuse_albedo`) of the material now
    in its slot (`other_slots`), NaN rows where the slot is -1 (the previewed vertices)."""
    rows = np.full((len(slots), 3), np.nan, dtype=np.float32)
    for k, mat in other_materials(obj, slots).items():
        rows[slots == k] = cycles.diffuse_albedo(mat)
    return rows


def export_scene(
    objects: list[bpy.types.Object], depsgraph=None, bl_scene: bpy.types.Scene | None = None,
    material: bpy.types.Material | None = None, others_scatter: bool = False,
) -> tuple[translucent.Scene, ExportInfo]:
    """One `translucent.Scene` from `objects` (their evaluated meshes merged) with the lights and
    world of `bl_scene`. With `material`, only the faces of that material are previewed, and an
    object with none of its faces in the material is left out (`info.without_faces`). Each
    object's faces of other materials:
    - by default cast shadows as an occluder ("NAME [other materials]") and only the previewed
      faces' vertices are exported (`ObjectRange.vertices`);
    - with `others_scatter` (PRT reading the Base Color per vertex) stay in the mesh, as Cycles'
      walk sees them: it can leave its object through a face of another material, where Cycles
      shades the exit with a diffuse lobe in that face's place (`subsurface_shader_data_setup`),
      so light entering there reaches the previewed faces. Their vertices scatter as their own
      material's diffuse albedo (`ObjectRange.others`) and are not previewed.
    `info.objects` says which vertex range belongs to which object."""
    bl_scene = bl_scene or bpy.context.scene
    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    info = ExportInfo()
    parts_p, parts_t, parts_n, others, glows = [], [], [], [], []
    offset = 0
    for obj in objects:
        if obj.type != "MESH":
            raise ValueError(f"{obj.name} is a {obj.type}, not a mesh")
        p, t, n, key, slots = _evaluate(obj, depsgraph, triangles=True)
        evaluated_count, vertices, albedo, kept_slots = len(p), None, None, None
        if material is not None:
            mine = np.isin(slots, list(material_slots(obj, material)))
            if not mine.any():
                info.without_faces.append(obj.name)
                continue
            if not mine.all() and any(cycles.emits(m) for m in other_materials(obj, np.where(mine, -1, slots)).values()):
                # Faces of another material that glow (eyes, a lamp's bulb): a light of their own.
                glows.append((obj, p, t, slots, ~mine))
            if not mine.all() and others_scatter:
                kept_slots = other_slots(t, slots, mine, len(p))
                if any(cycles.emits(m) for m in other_materials(obj, kept_slots).values()):
                    info.emitters.append(obj.name)
                albedo = others_now(obj, kept_slots)
            elif not mine.all():
                others.append((obj, p, t[~mine], slots[~mine]))
                vertices, t = np.unique(t[mine], return_inverse=True)
                t = t.reshape(-1, 3)
                p, n = p[vertices], n[vertices]
        parts_p.append(p)
        parts_t.append(t + offset)
        parts_n.append(n)
        info.objects.append(ObjectRange(obj.name, offset, len(p), key, vertices, evaluated_count, albedo, kept_slots))
        offset += len(p)
    if not parts_p:
        what = f"the faces of material {material.name!r}" if material is not None else "objects"
        raise ValueError(f"no {what} to export: " + (", ".join(info.without_faces) or "no objects")
                         + (" hold it in a slot but on none of their faces" if info.without_faces else ""))
    info.positions = np.concatenate(parts_p)
    # Each object its own medium: no light scatters from one into another (Cycles' walk stays
    # in its object), though they share the material and one transport.
    owners = np.repeat(np.arange(len(parts_p)), [len(p) for p in parts_p]) if len(parts_p) > 1 else None
    scene = translucent.Scene(info.positions, np.concatenate(parts_t), np.concatenate(parts_n), objects=owners)
    for obj, p, t, slots in others:
        # Faces of other materials (eyes, teeth, clothes) shadow the previewed faces as Cycles'
        # shadow rays see them, and send light back; they neither scatter nor receive the preview.
        _add_parts(scene, obj, f"{obj.name} [other materials]", p, t, slots, info, slot_materials(obj))
    add_occluders(scene, depsgraph, {o.name for o in objects}, info)
    for obj, p, t, slots, faces in glows:
        _add_emitter(obj, p, t, slots, info, slot_materials(obj), faces=faces)
    for obj in objects:
        if any(cycles.emits(s.material) for s in obj.material_slots):
            info.occluder_keys[f"glow {obj.name}"] = _glow_key(slot_materials(obj))  # as `occluder_keys` reads it
    # An emissive object hidden from shadow rays still lights the scene in Cycles: a light
    # that shadows nothing, not even its own far side (named where it cannot be read).
    for obj in _shadowless_emitters(bl_scene, {o.name for o in objects}):
        try:
            co, tris, _, key, slots = _evaluate(obj, depsgraph, triangles=True)
        except RuntimeError:
            continue
        materials = slot_materials(obj)
        _add_key(info.occluder_keys, obj, key, materials, kind="emitter")
        info.emitters.append(obj.name)
        if len(co) and len(tris):
            _add_emitter(obj, co, tris, slots, info, materials, visible_shadow=False)
    _bake_emitters(info)
    add_lights(scene, bl_scene, info)
    set_world(scene, bl_scene, info)
    return scene, info

