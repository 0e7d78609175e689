"""The scenes the scripts build in bpy and the materials they name: the demo's Suzanne (10 cm,
Subdivision Surface, a point light, a dim world, a camera), the same lit from behind, a shared
model under the demo's light, an open sheet under a sun, and the evaluated mesh as an object of
its own (for the preview's colour attribute and for vertex bakes)."""

from __future__ import annotations

import bpy
import numpy as np

import translucent

MM_PER_UNIT = 1000.0  # Blender units are metres

# Behind Suzanne's head (she faces -Y), a little above her ears.
BACKLIGHT = (0.0, 0.14, 0.06)

SHEET_SIZE = 0.1  # the open sheet's side [m]


def material(name: str) -> translucent.Material:
    """Jensen's measured presets at 1 mm = 1/1000 unit, mapped to Principled inputs (with
    Blender's default Roughness 0.5), or a Principled material with Subsurface Anisotropy 0.8."""
    if name == "aniso08":
        return translucent.Material.from_principled(
            base_color=(0.85, 0.65, 0.5), radius=(1.0, 0.45, 0.25), scale=0.005, anisotropy=0.8, ior=1.45,
            roughness=0.5)
    return translucent.Material.preset(name, MM_PER_UNIT)


def demo_scene() -> tuple[bpy.types.Object, bpy.types.Object]:
    """A new file holding a subdivided Suzanne about 10 cm across, a point light ("Key"), a
    camera and a dim world: Suzanne and the camera."""
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


def build_scene(model: str) -> tuple[bpy.types.Object, bpy.types.Object]:
    """The demo's scene (Suzanne with Subdivision, point light, dim world), the same lit from
    behind ("suzanne-backlit": the light behind the head, its ears between it and the camera),
    or a shared model at 10 cm under the demo's light: the object and the camera."""
    suzanne, cam = demo_scene()
    if model == "suzanne-backlit":
        bpy.data.objects["Key"].location = BACKLIGHT
        return suzanne, cam
    if model != "suzanne":
        from blender_scripts.lib import models

        p, t = models.load(model, diagonal=0.1)
        mesh = bpy.data.meshes.new(model)
        mesh.from_pydata(p.tolist(), [], t.tolist())
        mesh.shade_smooth()
        obj = bpy.data.objects.new(model, mesh)
        bpy.context.scene.collection.objects.link(obj)
        bpy.data.objects.remove(suzanne)
        return obj, cam
    return suzanne, cam


def preview_object(source: bpy.types.Object) -> bpy.types.Object:
    """A separate object holding the evaluated mesh, so the colour attribute can have one value
    per evaluated vertex (the Subdivision modifier changes the vertex count); it shows the
    add-on's attribute as emission. The source is hidden from renders."""
    from addon import writeback

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


def sheet(n: int, size: float, origin: float) -> bpy.types.Object:
    """An open square sheet of n x n vertices at z = 0, its edge at x = origin, under a sun."""
    h = size / (n - 1)
    p = [(origin + i * h, j * h, 0.0) for j in range(n) for i in range(n)]
    t = []
    for j in range(n - 1):
        for i in range(n - 1):
            a, b, c, d = j * n + i, j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i
            t += [(a, b, c), (a, c, d)]
    mesh = bpy.data.meshes.new("sheet")
    mesh.from_pydata(p, [], t)
    mesh.shade_smooth()
    obj = bpy.data.objects.new("sheet", mesh)
    bpy.context.scene.collection.objects.link(obj)
    sun = bpy.data.lights.new("sun", "SUN")
    sun.energy, sun.angle = 1.0, 0.0
    bpy.context.scene.collection.objects.link(bpy.data.objects.new("sun", sun))
    world = bpy.data.worlds.new("black")
    bpy.context.scene.world = world
    if world.node_tree is None:  # Blender < 5.0 (5.0 always has nodes; use_nodes is deprecated)
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    return obj


FLOOR_COLOUR = (0.6, 0.55, 0.5)


def floor_and_box(character: bpy.types.Object) -> list[bpy.types.Object]:
    """Issue 30's scene around the demo's Suzanne: a 1 m floor 1 mm under `character` (a
    Principled BSDF, FLOOR_COLOUR) and a 3 cm box a third of the way to the key light, beside
    the line to it (no material: Cycles' grey 0.8), casting its shadow across her."""
    from addon import export

    depsgraph = bpy.context.evaluated_depsgraph_get()
    p, _, _ = export.evaluated_mesh_arrays(character, depsgraph)
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


def texture_base_color(mat: bpy.types.Material, source: str) -> bpy.types.Node:
    """Links a texture into the Base Color of `mat`'s Principled BSDF, between the socket's
    colour and half of it: "procedural" (a Checker Texture, scale 6, in generated coordinates)
    or "image" (a 128 px float image of soft blotches through the UV map). Returns the node."""
    node = mat.node_tree.nodes["Principled BSDF"]
    colour = tuple(node.inputs["Base Color"].default_value)
    if source == "procedural":
        tex = mat.node_tree.nodes.new("ShaderNodeTexChecker")
        tex.inputs["Scale"].default_value = 6.0
        tex.inputs["Color1"].default_value = colour
        tex.inputs["Color2"].default_value = (*(0.5 * c for c in colour[:3]), 1.0)
    elif source == "image":
        n = 128
        u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
        blotch = 0.5 + 0.25 * (np.sin(9 * np.pi * u) * np.cos(7 * np.pi * v) + 1)
        px = np.ones((n, n, 4), np.float32)
        px[..., :3] = blotch[..., None] * np.asarray(colour[:3], np.float32)
        img = bpy.data.images.get("Blotches") or bpy.data.images.new("Blotches", n, n, float_buffer=True)
        img.pixels.foreach_set(px.ravel())
        tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
        tex.image = img
    else:
        raise ValueError(f"source must be 'procedural' or 'image', not {source!r}")
    mat.node_tree.links.new(tex.outputs["Color"], node.inputs["Base Color"])
    return tex


def smallest_parts(mesh: bpy.types.Mesh, count: int = 2) -> np.ndarray:
    """Per face of `mesh`, whether it lies in one of its `count` smallest loose parts (by faces;
    Suzanne's two eyes for the monkey primitive), the parts found by union-find over the faces'
    vertices."""
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
    face_root = np.array([find(poly.vertices[0]) for poly in mesh.polygons])
    parts, counts = np.unique(face_root, return_counts=True)
    return np.isin(face_root, parts[np.argsort(counts)[:count]])
