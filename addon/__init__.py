"""Translucent: subsurface-scattering preview for Blender (Jensen dipole, PRT after Xu 2007).

Blender-side code only: UI, scene export (`export`), colour write-back (`writeback`).
All maths lives in the native `translucent` module. The full editing UI is a later issue;
this registers a Material Properties panel that points at the Python API.
"""

import bpy


class TRANSLUCENT_PT_material(bpy.types.Panel):
    bl_label = "Translucent Preview"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "material"

    @classmethod
    def poll(cls, context):
        return context.material is not None

    def draw(self, context):
        layout = self.layout
        try:
            import translucent

            layout.label(text=f"translucent {translucent.__version__} loaded")
        except ImportError:
            layout.label(text="native module not installed", icon="ERROR")


classes = (TRANSLUCENT_PT_material,)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
