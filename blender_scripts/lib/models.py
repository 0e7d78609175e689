"""Test meshes from ../shared/models, scaled to a stated size, and the standard lighting the
benchmarks and accuracy checks use. Loading only: no maths beyond scaling to a size."""

from __future__ import annotations

import os
import pathlib

import numpy as np

import translucent

REPO = pathlib.Path(__file__).resolve().parents[2]
# TRANSLUCENT_MODELS points elsewhere (the device machine, where ../shared does not travel).
MODELS = pathlib.Path(os.environ.get("TRANSLUCENT_MODELS", REPO.parent / "shared" / "models"))


def load(name: str, diagonal: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Positions (N, 3) float32 and triangles (M, 3) int64 of a shared model, centred and
    scaled so its bounding-box diagonal is `diagonal` scene units (0.1 = 10 cm in metres)."""
    import trimesh  # a well-kept loader for OBJ/PLY

    path = MODELS / name
    if not path.exists():
        raise FileNotFoundError(f"{path} not found: the shared models live beside the repo")
    mesh = trimesh.load(path, process=False, force="mesh")
    p = np.asarray(mesh.vertices, dtype=np.float64)
    lo, hi = p.min(axis=0), p.max(axis=0)
    p = (p - 0.5 * (lo + hi)) * (diagonal / np.linalg.norm(hi - lo))
    t = np.asarray(mesh.faces, dtype=np.int64)
    # A closed mesh wound inwards (the shared horse.ply: signed volume < 0) has its normals
    # inside: the light would enter from within. Turn it outwards, as Blender's "Recalculate
    # Outside" would; open meshes (the bunny) are left as they are.
    if mesh.is_watertight and _signed_volume(p, t) < 0:
        t = t[:, ::-1].copy()
    return p.astype(np.float32), t


def _signed_volume(p: np.ndarray, t: np.ndarray) -> float:
    return float(np.einsum("ij,ij->i", p[t[:, 0]], np.cross(p[t[:, 1]], p[t[:, 2]])).sum() / 6.0)


def subdivide(positions: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Midpoint subdivision (each triangle into four): a bigger mesh of the same shape."""
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    unique, inverse = np.unique(edges, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    mids = 0.5 * (positions[unique[:, 0]] + positions[unique[:, 1]])
    n = len(positions)
    m = len(triangles)
    ab, bc, ca = (inverse[:m] + n, inverse[m : 2 * m] + n, inverse[2 * m :] + n)
    a, b, c = triangles.T
    tris = np.concatenate(
        [np.stack(t, axis=1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))]
    )
    return np.concatenate([positions, mids]).astype(np.float32), tris.astype(np.int64)


def standard_scene(positions: np.ndarray, triangles: np.ndarray) -> translucent.Scene:
    """The benchmark lighting: a key point light above-front and a dimmer sun from the back
    left, both white, no world (Blender units: metres, watts, W/m^2)."""
    scene = translucent.Scene(positions, triangles)
    diag = float(np.linalg.norm(positions.max(axis=0) - positions.min(axis=0)))
    scene.add_point_light((0.6 * diag, -1.0 * diag, 1.2 * diag), power=110.0 * diag**2)
    scene.add_sun(direction=(0.5, 0.6, -0.62), irradiance=2.0)
    return scene


def decimate(positions: np.ndarray, triangles: np.ndarray, vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """The mesh reduced to about `vertices` vertices by Blender's Decimate modifier (collapse),
    on a temporary object that is removed again: a coarse mesh of the same shape."""
    import bpy

    me = bpy.data.meshes.new("translucent_decimate")
    me.from_pydata(positions.tolist(), [], triangles.tolist())
    ob = bpy.data.objects.new("translucent_decimate", me)
    bpy.context.scene.collection.objects.link(ob)
    try:
        ob.modifiers.new("decimate", "DECIMATE").ratio = min(1.0, vertices / len(positions))
        ev = ob.evaluated_get(bpy.context.evaluated_depsgraph_get())
        out = ev.to_mesh()
        out.calc_loop_triangles()
        p = np.empty(3 * len(out.vertices), np.float32)
        out.vertices.foreach_get("co", p)
        t = np.empty(3 * len(out.loop_triangles), np.int64)
        out.loop_triangles.foreach_get("vertices", t)
        ev.to_mesh_clear()
    finally:
        bpy.data.objects.remove(ob)
        bpy.data.meshes.remove(me)
    return p.reshape(-1, 3), t.reshape(-1, 3)


def uv_sphere(rings: int, segments: int, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """A latitude-longitude sphere (outward winding) of (rings - 1) * segments + 2 vertices."""
    p = [(0.0, 0.0, radius)]
    for i in range(1, rings):
        th = np.pi * i / rings
        for j in range(segments):
            ph = 2.0 * np.pi * j / segments
            p.append((radius * np.sin(th) * np.cos(ph), radius * np.sin(th) * np.sin(ph), radius * np.cos(th)))
    p.append((0.0, 0.0, -radius))
    t = []
    for j in range(segments):
        t.append((0, 1 + j, 1 + (j + 1) % segments))
    for i in range(rings - 2):
        a, b = 1 + i * segments, 1 + (i + 1) * segments
        for j in range(segments):
            k = (j + 1) % segments
            t += [(a + j, b + j, b + k), (a + j, b + k, a + k)]
    last, base = len(p) - 1, 1 + (rings - 2) * segments
    for j in range(segments):
        t.append((last, base + (j + 1) % segments, base + j))
    return np.asarray(p, np.float32), np.asarray(t, np.int64)
