"""Cycles (and EEVEE) references of a scene built in bpy, cached on disk (issue 5, point 2).

- `bake_vertices`: Cycles' per-vertex bake of the diffuse passes (direct + indirect + colour:
  subsurface scattering lands there; specular reflection does not), with the material mapped
  to a Principled BSDF random walk by `translucent.cycles`.
- `bake_receivers`: the same at a few vertices only, at a cost that does not grow with the
  mesh (selected-to-active onto the corners' sample points), every sample taken.
- `render_image`: a camera render with Cycles or EEVEE (linear float RGBA).
- `render_beside`: the demo's camera render of the source object in the mapped material
  (PNG, not cached), beside the preview object it hides meanwhile.
- `use_cycles`: the one place the scripts and tests set Cycles up (engine, device, samples,
  seed, denoising).

Each result is cached under out/cache/cycles/<key>.npz, the key hashing the evaluated
geometry, the lights, the material and the settings; the wall time of the original render is
stored with it, so reports can plot it without rendering again.
"""

from __future__ import annotations

import contextlib
import hashlib
import pathlib
import tempfile
import time

import bpy
import numpy as np

import translucent
from translucent import cycles

from blender_scripts.lib.figures import write_png

REPO = pathlib.Path(__file__).resolve().parents[2]
CACHE = REPO / "out" / "cache" / "cycles"

# The sampling seed of bakes compared with a reference bake (which takes Cycles' default, 0).
# With the reference's own seed a bake's samples are the reference's first ones, and under
# adaptive sampling a point that converged early takes the same value in both: the cheaper
# bake would look less noisy than it is.
LADDER_SEED = 1


def _scene_digest(objects) -> str:
    # The key covers vertex positions, transforms, lights, camera and world, not the faces: a
    # winding flip or re-triangulation over the same positions is served the old result (found
    # when models.load turned the horse outwards; delete that entry in out/cache/cycles). Adding
    # the faces would invalidate every stored bake (hours of 1024-spp bakes on 2 cores).
    h = hashlib.sha256()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for o in objects:
        ev = o.evaluated_get(depsgraph)
        mesh = ev.to_mesh()
        co = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", co)
        ev.to_mesh_clear()
        h.update(co.tobytes())
        h.update(np.array(o.matrix_world, np.float32).tobytes())
    for o in bpy.context.scene.objects:
        if o.type in {"LIGHT", "CAMERA"}:
            h.update(np.array(o.matrix_world, np.float32).tobytes())
            if o.type == "LIGHT":
                d = o.data
                h.update(repr((d.type, d.energy, tuple(d.color), d.shadow_soft_size)).encode())
    w = bpy.context.scene.world
    if w is not None and w.node_tree is not None:
        bg = next((n for n in w.node_tree.nodes if n.type == "BACKGROUND"), None)
        if bg is not None:
            h.update(repr((tuple(bg.inputs["Color"].default_value), bg.inputs["Strength"].default_value)).encode())
    return h.hexdigest()


def _cached(key: str, compute):
    path = CACHE / f"{key}.npz"
    if path.exists():
        z = np.load(path)
        return z["values"], float(z["seconds"])
    t0 = time.perf_counter()
    values = compute()
    seconds = time.perf_counter() - t0
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, values=values, seconds=seconds)
    return values, seconds


def _material_key(material: translucent.Material) -> tuple:
    return (material.sigma_a, material.sigma_s, material.g, material.eta, material.roughness,
            material.subsurface_weight, material.metallic, material.transmission)


def principled_material(material: translucent.Material, name: str = "Cycles reference") -> bpy.types.Material:
    """A Principled BSDF random walk simulating `material` (medium per scene unit, layers)."""
    p = cycles.principled_for(material)
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # Blender < 5.0 (5.0 always has nodes; use_nodes is deprecated)
        mat.use_nodes = True
    cycles.apply_to_principled(mat.node_tree.nodes["Principled BSDF"], p)
    return mat


def _with_material(obj, mat):
    old = [s.material for s in obj.material_slots]
    if not obj.material_slots:
        obj.data.materials.append(mat)
    for s in obj.material_slots:
        s.material = mat
    return old


def use_cycles(samples: int, seed: int = 0, denoising: bool = False) -> bpy.types.Scene:
    """Cycles on the CPU at `samples` with `seed`, the denoiser on or off (the other settings as
    the scene has them: Blender's default adaptive sampling). References take the defaults, no
    denoising: a denoised answer is not Cycles' estimate."""
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = denoising
    scene.cycles.seed = seed
    return scene


@contextlib.contextmanager
def _cycles_sampling(samples: int, seed: int, adaptive: bool):
    """Cycles at `samples` and `seed` (`use_cycles`), adaptive sampling on or off while the block
    runs, the scene's adaptive sampling as it was afterwards."""
    scene = use_cycles(samples, seed)
    was_adaptive = scene.cycles.use_adaptive_sampling
    scene.cycles.use_adaptive_sampling = adaptive
    try:
        yield scene
    finally:
        scene.cycles.use_adaptive_sampling = was_adaptive


@contextlib.contextmanager
def _simulated_in_cycles(obj: bpy.types.Object, material: translucent.Material, samples: int, seed: int,
                         adaptive: bool):
    """Cycles at `samples` and `seed`, adaptive sampling on or off (`_cycles_sampling`), and `obj`
    in the Principled simulation of `material` (`principled_material`, yielded) while the block
    runs; afterwards the object's materials as they were, the mapped one removed."""
    with _cycles_sampling(samples, seed, adaptive):
        mat = principled_material(material)
        old = _with_material(obj, mat)
        try:
            yield mat
        finally:
            for s, m in zip(obj.material_slots, old):
                s.material = m
            bpy.data.materials.remove(mat)


def _diffuse_passes(direct_only: bool) -> set[str]:
    """The diffuse bake's passes: light times colour, with or without indirect light."""
    return {"DIRECT", "COLOR"} if direct_only else {"DIRECT", "INDIRECT", "COLOR"}


def bake_diffuse_vertex_colors(obj: bpy.types.Object, passes: set[str], also_selected=(), **options) -> np.ndarray:
    """Cycles' diffuse bake of `passes` (Blender's pass filter: "DIRECT", "INDIRECT", "COLOR")
    into a temporary colour attribute of `obj` (a mesh with no modifiers), read back per vertex,
    (N, 3), the attribute removed again. `obj` is the active object; `also_selected` are
    selected beside it and `options` go to `bpy.ops.object.bake` (for "selected to active").
    Cycles and its settings as the scene has them."""
    mesh = obj.data
    attr = mesh.color_attributes.new("cycles_bake", "FLOAT_COLOR", "POINT")
    try:
        mesh.color_attributes.active_color = attr
        bpy.ops.object.select_all(action="DESELECT")
        for o in (obj, *also_selected):
            o.select_set(True)
        bpy.context.view_layer.objects.active = obj
        bpy.ops.object.bake(type="DIFFUSE", pass_filter=passes, target="VERTEX_COLORS", **options)
        px = np.empty(len(mesh.vertices) * 4, np.float32)
        mesh.color_attributes["cycles_bake"].data.foreach_get("color", px)
    finally:
        mesh.color_attributes.remove(mesh.color_attributes["cycles_bake"])
    return px.reshape(-1, 4)[:, :3]


def bake_vertices(obj: bpy.types.Object, material: translucent.Material, samples: int, direct_only: bool = False,
                  seed: int = 0, adaptive: bool = True) -> tuple[np.ndarray, float]:
    """Cycles' diffuse radiance (direct + indirect + colour) per vertex of `obj` (a mesh with
    no modifiers), (N, 3), and the bake's wall time [s]. `direct_only` leaves out indirect
    light (the object's own interreflection); `seed` is Cycles' sampling seed. `adaptive`:
    Blender's default adaptive sampling (noise threshold 0.01), where `samples` is the most a
    point gets; without it every point gets them all. Cached under a key that names every
    other mesh Cycles renders beside `obj`."""
    extra = () if not direct_only and seed == 0 else (direct_only, seed)
    if not adaptive:
        extra += ("every sample",)
    # Other meshes Cycles renders beside `obj` (a floor, a prop) change the bake, so they are in
    # the key; a lone object's key is as it always was, so its stored bakes stay valid.
    others = sorted((o for o in bpy.context.scene.objects if o.type == "MESH" and not o.hide_render and o != obj),
                    key=lambda o: o.name)
    if others:
        extra += ("beside", [o.name for o in others], _scene_digest(others))
    key = hashlib.sha256(repr(("bake", _scene_digest([obj]), *_material_key(material)[:4], samples, *extra,
                               *_material_key(material)[4:])).encode()).hexdigest()[:24]

    def compute():
        with _simulated_in_cycles(obj, material, samples, seed, adaptive):
            return bake_diffuse_vertex_colors(obj, _diffuse_passes(direct_only))

    return _cached(key, compute)


def bake_whole_scene(copy: bpy.types.Object, materials: list, samples: int, label: str) -> tuple[np.ndarray, float]:
    """Cycles' diffuse bake (direct, indirect, colour) of `copy` (a mesh with no modifiers) in the
    whole scene as it stands, its slots holding the Blender `materials`, at `samples` with every
    sample taken (seed 0), (N, 3), and its wall time [s]. Cached: the key hashes every mesh
    object Cycles renders (their positions and transforms), the lights, the world, `samples` and
    `label`, which must name what the key does not see (the materials' nodes and textures)."""
    shown = sorted((o for o in bpy.context.scene.objects if o.type == "MESH" and not o.hide_render),
                   key=lambda o: o.name)
    key = hashlib.sha256(repr(("whole scene", _scene_digest(shown), [o.name for o in shown], samples,
                               label)).encode()).hexdigest()[:24]

    def compute():
        copy.data.materials.clear()
        for mat in materials:
            copy.data.materials.append(mat)
        with _cycles_sampling(samples, 0, adaptive=False):
            return bake_diffuse_vertex_colors(copy, _diffuse_passes(False))

    return _cached(key, compute)


def bake_receivers(obj: bpy.types.Object, material: translucent.Material, samples: int, receivers,
                   direct_only: bool = True, seed: int = 0) -> tuple[np.ndarray, float]:
    """Cycles' diffuse radiance at a few vertices of `obj` (a triangle mesh with no modifiers),
    (len(receivers), 3), as `bake_vertices` gives it there, and the bake's wall time [s]; at
    `samples` per sample point without adaptive sampling (every sample is taken).

    A vertex bake shades every corner of the mesh; this one only the receivers' corners, so its
    cost does not grow with the mesh (the horse: 60 of 48,485 vertices). Blender bakes a vertex
    as the mean over its corners of Cycles' answer at the vertex moved towards the corner
    triangle's centroid by min(that distance, 1e-4 max(1, max |P|)) (Cycles'
    `bake_offset_towards_center`). Here each receiver corner becomes a lone triangle of a
    separate object whose first vertex is that point, in the corner triangle's plane, baked
    "selected to active" onto `obj`: Blender casts a ray at each of its vertices onto `obj` and
    Cycles shades `obj` at the hit, the same point (not a vertex, so Cycles does not move it
    again). The receivers' corners sample the same points as the vertex bake; the lone
    triangles' other vertices are discarded. The helper object is invisible to every ray."""
    receivers = np.asarray(receivers, np.int64)
    extra = (direct_only, seed, hashlib.sha256(receivers.tobytes()).hexdigest())
    key = hashlib.sha256(repr(("receivers", _scene_digest([obj]), *_material_key(material)[:4], samples, *extra,
                               *_material_key(material)[4:])).encode()).hexdigest()[:24]

    def compute():
        mesh = obj.data
        if any(len(p.vertices) != 3 for p in mesh.polygons):
            raise ValueError("bake_receivers needs a triangle mesh")
        if receivers.size == 0 or receivers.min() < 0 or receivers.max() >= len(mesh.vertices):
            raise ValueError("receivers must be vertex indices of the mesh")
        tri = np.empty(len(mesh.polygons) * 3, np.int64)
        mesh.polygons.foreach_get("vertices", tri)
        tri = tri.reshape(-1, 3)
        co = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", co)
        m = np.array(obj.matrix_world, np.float64)
        # Cycles applies the object's transform to a non-instanced mesh: the offset is in world space.
        world = co.reshape(-1, 3).astype(np.float64) @ m[:3, :3].T + m[:3, 3]
        slot = np.full(len(mesh.vertices), -1)
        slot[receivers] = np.arange(len(receivers))
        # The receivers' corners (triangle, corner), in triangle order.
        at, corner = np.nonzero(slot[tri] >= 0)
        if len(np.unique(tri[at, corner])) < len(np.unique(receivers)):
            raise ValueError("every receiver must be a corner of a triangle (a vertex bake has nothing for it)")
        points, owner = [], []
        for t, c in zip(tri[at], corner):
            v, a, b = world[t[c]], world[t[(c + 1) % 3]], world[t[(c + 2) % 3]]
            to_centre = (v + a + b) / 3.0 - v
            length = np.linalg.norm(to_centre)
            points += [v + to_centre / length * min(length, max(np.abs(v).max(), 1.0) * 1e-4), a, b]
            owner.append(slot[t[c]])
        size = float(np.ptp(world, axis=0).max())
        helper_mesh = bpy.data.meshes.new("Translucent receivers")
        helper_mesh.from_pydata(points, [], np.arange(len(points)).reshape(-1, 3).tolist())
        helper_mesh.uv_layers.new(name="UVMap")  # selected-to-active needs UV maps on both (Blender 5.0 crashes)
        helper = bpy.data.objects.new("Translucent receivers", helper_mesh)
        bpy.context.scene.collection.objects.link(helper)
        for flag in ("visible_camera", "visible_diffuse", "visible_glossy", "visible_transmission",
                     "visible_volume_scatter", "visible_shadow"):
            setattr(helper, flag, False)
        added_uv = not mesh.uv_layers
        if added_uv:
            mesh.uv_layers.new(name="Translucent bake")
        try:
            with _simulated_in_cycles(obj, material, samples, seed, adaptive=False) as mat:
                helper_mesh.materials.append(mat)
                # A ray from 1e-4 of the mesh's size above each point, back along the normal onto `obj`.
                px = bake_diffuse_vertex_colors(helper, _diffuse_passes(direct_only), also_selected=(obj,),
                                                use_selected_to_active=True, cage_extrusion=1e-4 * size,
                                                max_ray_distance=3e-4 * size)
        finally:
            bpy.data.objects.remove(helper)
            bpy.data.meshes.remove(helper_mesh)
            if added_uv:
                mesh.uv_layers.remove(mesh.uv_layers["Translucent bake"])
        first = px.reshape(-1, 3, 3)[:, 0, :].astype(np.float64)
        values = np.zeros((len(receivers), 3))
        np.add.at(values, np.array(owner), first)
        return (values / np.bincount(owner, minlength=len(receivers))[:, None]).astype(np.float32)

    return _cached(key, compute)


def render_exr(scene: bpy.types.Scene) -> np.ndarray:
    """A render of `scene` as it is set (engine, camera, resolution) through a temporary linear
    OpenEXR file: (height, width, 4) RGBA, float32, top row first."""
    scene.render.image_settings.file_format = "OPEN_EXR"
    with tempfile.TemporaryDirectory() as tmp:
        scene.render.filepath = str(pathlib.Path(tmp) / "frame.exr")
        bpy.ops.render.render(write_still=True)
        img = bpy.data.images.load(scene.render.filepath)
        try:
            width, height = img.size
            return np.array(img.pixels[:], dtype=np.float32).reshape(height, width, 4)[::-1]
        finally:
            bpy.data.images.remove(img)


def use_engine(engine: str, samples: int) -> bpy.types.Scene:
    """The scene set to render with "CYCLES" (`use_cycles`, no denoising) or "EEVEE" (Blender
    5.0's EEVEE at `samples`); RuntimeError where this Blender has no EEVEE."""
    if engine == "CYCLES":
        return use_cycles(samples)
    scene = bpy.context.scene
    names = [e.identifier for e in bpy.types.RenderSettings.bl_rna.properties["engine"].enum_items]
    eevee = next((n for n in ("BLENDER_EEVEE", "BLENDER_EEVEE_NEXT") if n in names), None)
    if eevee is None:
        raise RuntimeError(f"no EEVEE engine in this Blender (engines: {names})")
    scene.render.engine = eevee
    scene.eevee.taa_render_samples = samples
    return scene


def render_image(obj: bpy.types.Object, material: translucent.Material, samples: int, engine: str = "CYCLES",
                 size: int = 128) -> tuple[np.ndarray, float]:
    """A camera render of the scene with `obj` in the mapped material: (size, size, 4) linear
    RGBA (alpha = coverage, transparent film), and its wall time [s]. `engine` is "CYCLES" or
    "EEVEE" (Blender 5.0's EEVEE, its own screen-space subsurface scattering)."""
    key = hashlib.sha256(repr(("image", engine, _scene_digest([obj]), *_material_key(material)[:4], samples, size,
                               *_material_key(material)[4:])).encode()).hexdigest()[:24]

    def compute():
        scene = use_engine(engine, samples)
        scene.render.film_transparent = True
        scene.render.resolution_x = scene.render.resolution_y = size
        scene.view_settings.view_transform = "Standard"
        mat = principled_material(material)
        old = _with_material(obj, mat)
        try:
            return render_exr(scene)
        finally:
            for s, m in zip(obj.material_slots, old):
                s.material = m
            bpy.data.materials.remove(mat)

    return _cached(key, compute)


def render_beside(source: bpy.types.Object, preview: bpy.types.Object, material: translucent.Material,
                  samples: int, path: pathlib.Path, bl_material: bpy.types.Material | None = None) -> None:
    """The scene's camera view in Cycles, written to `path` (PNG, 256 px, not cached): the
    source object (modifiers and all) in the Principled BSDF random walk mapped from `material`
    (`principled_material`), the preview object hidden meanwhile. Seed 0 and Blender's denoiser
    on, as a new file has them: a picture to look at beside the preview, not a reference.
    `bl_material`, where given, is rendered instead of the mapping (a textured material)."""
    mat = bl_material or principled_material(material, "Cycles " + path.stem)
    source.data.materials.clear()
    source.data.materials.append(mat)
    source.hide_render, preview.hide_render = False, True
    write_png(use_cycles(samples, seed=0, denoising=True), path)
    source.hide_render, preview.hide_render = True, False
