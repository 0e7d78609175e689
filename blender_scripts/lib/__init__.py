"""The library the scripts in blender_scripts/ are thin command lines over, and the tests import
(never a script). One module per concept:

- `cycles_reference`: Cycles' vertex bakes, bakes at a few vertices and camera renders of the
  mapped Principled material, cached on disk; `use_cycles`, the one place Cycles is set up;
  `bake_diffuse_vertex_colors` (the one vertex bake) and `render_exr` (a render read back).
- `ground_truth`: `translucent.reference_radiosity` cached on disk, and what a bake sees of it.
- `metrics`: relative RMS, mean ratio, one bake's noise from several seeds, the image metric.
- `scenes`: the scenes built in bpy (the demo's Suzanne, lit from behind, shared models, an open
  sheet), the materials by name, the evaluated mesh as an object of its own.
- `figures`: the preview rendered as the viewport shows it, `write_png`, renders in a labelled grid.
- `models`: the shared test meshes loaded at a stated size, and the standard lighting.
- `accuracy`: PRT against the ground truth on a shared model.
- `machine`: the machine a measurement ran on.

Import as `from blender_scripts.lib import metrics` with the repository root on sys.path.
`cycles_reference`, `scenes`, `figures.render_preview` and `figures.write_png` need bpy; the rest does not."""
