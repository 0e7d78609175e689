"""The images the scripts write: the preview rendered as the viewport shows it (Workbench, flat,
colour by attribute), and renders set side by side."""

from __future__ import annotations

import pathlib

import numpy as np


def render_preview(path: pathlib.Path) -> None:
    """The preview as the viewport shows it: Workbench, flat lighting, colour by attribute,
    256 px, PNG."""
    import bpy

    scene = bpy.context.scene
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.display.shading.light = "FLAT"
    scene.display.shading.color_type = "VERTEX"
    scene.render.resolution_x = scene.render.resolution_y = 256
    scene.render.film_transparent = False
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)


def side_by_side(left: pathlib.Path, right: pathlib.Path, path: pathlib.Path) -> None:
    """Two renders of one size side by side."""
    import matplotlib.image as mpimg

    a, b = mpimg.imread(left), mpimg.imread(right)
    mpimg.imsave(path, np.concatenate([a[..., :3], b[..., :3]], axis=1))
