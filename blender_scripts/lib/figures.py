"""The images the scripts write: the preview rendered as the viewport shows it (Workbench, flat,
colour by attribute), and renders set side by side in a grid that names every panel (a strip
of column titles above, row titles at the left; the renders themselves pixel for pixel)."""

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
    scene.render.film_transparent = False
    write_png(scene, path)


def write_png(scene, path: pathlib.Path, size: int = 256) -> None:
    """Renders `scene` with its engine as it is set, `size` px square, Blender's Standard view
    transform, to the PNG `path`."""
    import bpy

    scene.render.resolution_x = scene.render.resolution_y = size
    scene.view_settings.view_transform = "Standard"
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)


def side_by_side(left: pathlib.Path, right: pathlib.Path, path: pathlib.Path) -> None:
    """Two renders of one size side by side, unlabelled (the demo's per-material pairs)."""
    import matplotlib.image as mpimg

    a, b = mpimg.imread(left), mpimg.imread(right)
    mpimg.imsave(path, np.concatenate([a[..., :3], b[..., :3]], axis=1))


def labelled_grid(images: list[list[np.ndarray]], path: pathlib.Path, columns: list[str],
                  rows: list[str] | None = None, note: str | None = None, header_lines: int = 2) -> None:
    """Writes the renders `images[row][column]` (float RGB(A) in [0, 1], one size) as one PNG:
    each column titled by `columns` above it, each row by `rows` at its left (rotated), `note`
    in a line at the bottom. The renders keep their pixels (placed, not resampled)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    dpi = 100
    h, w = images[0][0].shape[:2]
    line = 13  # px per line of 9 pt text at 100 dpi
    top = 6 + line * header_lines
    left = 22 if rows else 0
    bottom = line + 6 if note else 0
    n_rows, n_cols = len(images), len(images[0])
    width, height = left + n_cols * w, top + n_rows * h + bottom
    fig = plt.figure(figsize=(width / dpi, height / dpi), dpi=dpi, facecolor="white")
    for r, row in enumerate(images):
        for c, img in enumerate(row):
            # figimage's offsets are from the bottom left, in pixels.
            fig.figimage(np.clip(img[..., :3], 0.0, 1.0), xo=left + c * w, yo=bottom + (n_rows - 1 - r) * h,
                         origin="upper")
    for c, text in enumerate(columns):
        fig.text((left + (c + 0.5) * w) / width, 1 - 3 / height, text, ha="center", va="top", fontsize=9,
                 linespacing=1.1)
    for r, text in enumerate(rows or ()):
        fig.text(3 / width, (bottom + (n_rows - r - 0.5) * h) / height, text, ha="left", va="center",
                 rotation=90, fontsize=9)
    if note:
        fig.text(0.5, 3 / height, note, ha="center", va="bottom", fontsize=8, color="0.3")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi, facecolor="white")
    plt.close(fig)
