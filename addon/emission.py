"""An emitter's textured or mixed emission (an Emission shader's Color from an image, a Mix
Shader of an Emission and a BSDF, a Principled BSDF's Emission driven by a procedural): Cycles'
emission pass baked at each face corner of a temporary copy of the emitter's evaluated mesh
(`bake.emission`), for a mesh light of that radiance per corner
(`translucent.Scene.add_mesh_light(corner_colors=...)`). Blender evaluates the nodes; the
add-on re-implements none. The copy is removed again; the user's data is only read."""

from __future__ import annotations

import bpy
import numpy as np

from . import bake


def _surface_nodes(mat: bpy.types.Material) -> list:
    """The nodes upstream of the active Material Output's Surface (what the emission pass
    reads)."""
    tree = None if mat is None else mat.node_tree
    out = None if tree is None else next((n for n in tree.nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output),
                                         None)
    if out is None:
        return []
    return bake.upstream([link.from_node for link in out.inputs["Surface"].links])


def key(mat: bpy.types.Material) -> str:
    """What a bake of `mat`'s emission depends on, as a digest (`bake.nodes_key` of the nodes
    upstream of its Surface): equal keys, the same bake."""
    return bake.nodes_key(_surface_nodes(mat))


def corner_radiance(obj: bpy.types.Object, mesh: bpy.types.Mesh, matrix, tris: np.ndarray) -> np.ndarray:
    """The radiance Cycles' emission pass gives at each corner of `obj`'s exported triangles
    `tris` (`export._evaluate`'s, turned back where `matrix` mirrors), as a (T, 3, 3) float32
    array [W/(m^2 sr)]. `mesh`: a temporary copy of the evaluated mesh `tris` came from
    (`export.evaluated_copy`, the caller's to remove), placed at `matrix`. Raises ValueError
    when the bake fails or the copy is not the exported mesh."""
    mesh.calc_loop_triangles()
    count = len(mesh.loop_triangles)
    vertices = np.empty(count * 3, dtype=np.int64)
    loops = np.empty(count * 3, dtype=np.int64)
    mesh.loop_triangles.foreach_get("vertices", vertices)
    mesh.loop_triangles.foreach_get("loops", loops)
    vertices, loops = vertices.reshape(-1, 3), loops.reshape(-1, 3)
    if np.linalg.det(np.array(matrix, dtype=np.float64)[:3, :3]) < 0.0:
        vertices, loops = vertices[:, ::-1], loops[:, ::-1]
    if vertices.shape != tris.shape or not np.array_equal(vertices, tris):
        raise ValueError("its evaluated mesh is not the one exported")
    # Object-level material links are the object's, not the mesh copy's.
    linked = [(k, s.material) for k, s in enumerate(obj.material_slots) if s.link == "OBJECT"]
    (corners,) = bake.emission([(mesh, matrix, linked)], domain="CORNER")
    return np.maximum(corners[loops], 0.0).astype(np.float32)
