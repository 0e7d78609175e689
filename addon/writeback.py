"""Write per-vertex colours into the add-on's own colour attribute, never any other data."""

from __future__ import annotations

import bpy
import numpy as np

ATTRIBUTE = "translucent_preview"


def write_colors(mesh: bpy.types.Mesh, colors: np.ndarray, name: str = ATTRIBUTE) -> bpy.types.Attribute:
    """Store (N,3) linear RGB in the POINT-domain FLOAT_COLOR attribute `name` of `mesh`
    (alpha 1), creating it if needed. The mesh must have N vertices."""
    colors = np.asarray(colors, dtype=np.float32)
    n = len(mesh.vertices)
    if colors.shape != (n, 3):
        raise ValueError(f"colors must have shape ({n}, 3) for mesh {mesh.name!r}, got {colors.shape}")
    attr = mesh.color_attributes.get(name)
    if attr is not None and (attr.domain != "POINT" or attr.data_type != "FLOAT_COLOR"):
        mesh.color_attributes.remove(attr)
        attr = None
    if attr is None:
        attr = mesh.color_attributes.new(name, "FLOAT_COLOR", "POINT")
    rgba = np.ones((n, 4), dtype=np.float32)
    rgba[:, :3] = colors
    attr.data.foreach_set("color", rgba.ravel())
    mesh.update()
    return attr


def split(values: np.ndarray, info) -> dict[str, np.ndarray]:
    """Per-object slices of an exported scene's per-vertex values (see export.ExportInfo)."""
    return {r.name: values[r.start : r.start + r.count] for r in info.objects}
