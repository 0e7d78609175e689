"""Write per-vertex colours into the add-on's own colour attribute, never any other data."""

from __future__ import annotations

import bpy
import numpy as np

ATTRIBUTE = "translucent_preview"


# What a vertex the preview does not cover (faces of another material only) shows in a preview
# attribute created anew: Blender's default viewport colour of a material.
UNCOVERED = (0.8, 0.8, 0.8)


def write_colors(mesh: bpy.types.Mesh, colors: np.ndarray, name: str = ATTRIBUTE) -> bpy.types.Attribute:
    """Store (N,3) linear RGB in the POINT-domain FLOAT_COLOR attribute `name` of `mesh`
    (alpha 1), creating it if needed. The mesh must have N vertices. Rows of NaN (vertices the
    preview does not cover) keep what the attribute held, or `UNCOVERED` in a new one."""
    colors = np.asarray(colors, dtype=np.float32)
    n = len(mesh.vertices)
    if colors.shape != (n, 3):
        raise ValueError(f"colors must have shape ({n}, 3) for mesh {mesh.name!r}, got {colors.shape}")
    attr = mesh.color_attributes.get(name)
    if attr is not None and (attr.domain != "POINT" or attr.data_type != "FLOAT_COLOR"):
        mesh.color_attributes.remove(attr)
        attr = None
    uncovered = np.isnan(colors).any(axis=1)
    rgba = np.ones((n, 4), dtype=np.float32)
    if attr is None:
        attr = mesh.color_attributes.new(name, "FLOAT_COLOR", "POINT")
        rgba[:, :3] = UNCOVERED
    elif uncovered.any():
        attr.data.foreach_get("color", rgba.ravel())
    rgba[~uncovered, :3] = colors[~uncovered]
    rgba[~uncovered, 3] = 1.0
    attr.data.foreach_set("color", rgba.ravel())
    mesh.update()
    return attr


def per_object(values: np.ndarray, info) -> dict[str, np.ndarray]:
    """Per-object values of an exported scene's per-vertex `values` (see export.ExportInfo), on
    each object's evaluated vertices: NaN rows where the object's vertices were not exported or
    are not previewed (faces of another material only)."""
    out = {}
    for r in info.objects:
        part = values[r.start : r.start + r.count]
        if r.others is not None:
            part = np.where(np.isnan(r.others[:, :1]), part, np.nan).astype(np.float32)
        if r.vertices is not None:
            full = np.full((r.evaluated_count, part.shape[1]), np.nan, dtype=np.float32)
            full[r.vertices] = part
            part = full
        out[r.name] = part
    return out
