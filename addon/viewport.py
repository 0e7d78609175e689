"""Show the preview in the 3D viewports while it is on, and put back what was there when it is
turned off: each previewed mesh's active colour attribute points at the add-on's attribute,
and Solid-mode viewports colour by attribute. Viewports in Material Preview or Rendered mode
are left as the artist set them. What was there before is remembered here and restored."""

from __future__ import annotations

import bpy

from . import writeback

# mesh name -> the active colour attribute it had before (None: none)
_ACTIVE: dict[str, str | None] = {}
# (screen name, area index) -> the Solid shading colour type it had before
_SHADING: dict[tuple[str, int], str] = {}


def _solid_viewports():
    for screen in bpy.data.screens:
        for i, area in enumerate(screen.areas):
            if area.type != "VIEW_3D":
                continue
            space = area.spaces.active
            if space is not None and space.type == "VIEW_3D" and space.shading.type == "SOLID":
                yield (screen.name, i), space.shading, area


def show(objects) -> None:
    """Point each object's mesh at the preview attribute and Solid viewports at attributes."""
    for obj in objects:
        mesh = obj.data
        attrs = mesh.color_attributes
        if attrs.get(writeback.ATTRIBUTE) is None:
            continue
        if mesh.name not in _ACTIVE:
            _ACTIVE[mesh.name] = attrs.active_color_name or None
        attrs.active_color_name = writeback.ATTRIBUTE
    for key, shading, area in _solid_viewports():
        if key not in _SHADING:
            _SHADING[key] = shading.color_type
        shading.color_type = "VERTEX"  # shown as "Attribute" in the Solid shading popover
        area.tag_redraw()


def restore(objects=None) -> None:
    """Put back the active colour attributes (of `objects`, or all) and, when no preview is left
    on, the viewports' shading colour."""
    names = None if objects is None else {o.data.name for o in objects}
    for mesh_name in list(_ACTIVE):
        if names is not None and mesh_name not in names:
            continue
        previous = _ACTIVE.pop(mesh_name)
        mesh = bpy.data.meshes.get(mesh_name)
        if mesh is None:
            continue
        if previous is not None and mesh.color_attributes.get(previous) is not None:
            mesh.color_attributes.active_color_name = previous
    if _ACTIVE:
        return
    for key, shading, area in _solid_viewports():
        if key in _SHADING:
            shading.color_type = _SHADING.pop(key)
            area.tag_redraw()
    _SHADING.clear()


def forget() -> None:
    """A new file: nothing to restore in it."""
    _ACTIVE.clear()
    _SHADING.clear()
