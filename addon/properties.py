"""Settings of the preview, stored on the material (they save with the .blend file).
Coefficients are shown per millimetre (Jensen's table units); `mm_per_unit` converts."""

from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty

from . import session


def _preset_items(self, context):
    try:
        import translucent

        names = translucent.Material.preset_names()
    except ImportError:
        names = []
    return [("CUSTOM", "Custom", "Coefficients as set below")] + [
        (n.upper(), n.capitalize(), f"Jensen 2001 measured {n}") for n in names
    ]


def _apply_preset(self, context):
    if self.preset == "CUSTOM":
        return
    import translucent

    m = translucent.Material.preset(self.preset.lower(), mm_per_unit=1.0)
    self["sigma_a"] = m.sigma_a
    self["sigma_s"] = m.sigma_s
    self["g"] = 0.0
    self["eta"] = m.eta
    _live_edit(self, context)


def _live_edit(self, context):
    session.edit(self.id_data)


def _principled(mat):
    tree = mat.node_tree
    if tree is None:
        return None
    return next((n for n in tree.nodes if n.type == "BSDF_PRINCIPLED"), None)


def read_from_principled(settings) -> bool:
    """Start from the material's own Principled BSDF: its subsurface inputs mapped to the
    medium Cycles would simulate (`translucent.cycles`). Returns whether it did."""
    from translucent import cycles

    node = _principled(settings.id_data)
    if node is None or node.inputs["Subsurface Weight"].default_value <= 0.0:
        return False
    p = cycles.read_principled(node)
    try:
        sigma_a, sigma_s, g, eta = cycles.from_principled(p.base_color, p.radius, p.scale, p.anisotropy, p.ior)
    except ValueError:
        return False
    k = settings.mm_per_unit  # coefficients are per scene unit; the panel shows them per mm
    settings["sigma_a"] = tuple(x / k for x in sigma_a)
    settings["sigma_s"] = tuple(x / k for x in sigma_s)
    settings["g"] = g
    settings["eta"] = min(eta, 2.5)
    settings["preset"] = 0  # Custom
    return True


def _toggle(self, context):
    """Turning the preview on the first time starts from the material's Principled BSDF;
    turning it off puts the viewports and active colour attributes back; on again shows the
    transport if there is one."""
    from . import viewport

    mat = self.id_data
    if self.enabled and not self.initialised:
        self["initialised"] = True
        read_from_principled(self)
    sess = session.SESSIONS.get(mat.name)
    objects = [o for o in (bpy.data.objects.get(n) for n in sess.objects) if o is not None] if sess else []
    if self.enabled and sess is not None:
        session.edit(mat)
        viewport.show(objects)
    elif not self.enabled:
        viewport.restore(objects or session.objects_with(mat))


class TranslucentMaterialSettings(bpy.types.PropertyGroup):
    enabled: BoolProperty(
        name="Preview", description="Show a subsurface-scattering preview of this material", default=False, update=_toggle
    )
    initialised: BoolProperty(
        name="Initialised", description="Settings were read from the material once", default=False,
        options={"HIDDEN"},
    )
    preset: EnumProperty(name="Preset", items=_preset_items, update=_apply_preset)
    sigma_a: FloatVectorProperty(
        name="Absorption", description="sigma_a per channel [1/mm]", size=3, min=0.0, soft_max=10.0,
        default=(0.0021, 0.0041, 0.0071), precision=4, update=_live_edit,
    )
    sigma_s: FloatVectorProperty(
        name="Scattering", description="sigma_s per channel [1/mm]", size=3, min=0.0, soft_max=50.0,
        default=(2.19, 2.62, 3.00), precision=3, update=_live_edit,
    )
    g: FloatProperty(name="Anisotropy g", description="Phase-function mean cosine", min=-0.99, max=0.99, default=0.0, update=_live_edit)
    eta: FloatProperty(name="IOR", description="Relative index of refraction (changing it needs a new precompute)", min=1.0, max=2.5, default=1.3)
    mm_per_unit: FloatProperty(name="mm per unit", description="Millimetres per scene unit (1000 for metres)", min=1e-6, default=1000.0)
    coefficients: IntProperty(name="Basis size", description="Coefficients of the piecewise polynomial basis (Xu 2007)", min=4, max=128, default=32)
    degree: EnumProperty(name="Degree", items=[("1", "Linear", "C0 piecewise linear"), ("2", "Quadratic", "C1 piecewise quadratic")], default="1")
    auto_refresh: BoolProperty(
        name="Auto refresh",
        description="When an edit leaves the range the basis was chosen for (the error estimate says so), "
        "precompute again in the background",
        default=True,
    )
    backend: EnumProperty(
        name="Device",
        items=[("auto", "Auto", "A GPU if there is one, else the CPU"), ("gpu", "GPU", "wgpu compute"), ("cpu", "CPU", "rayon")],
        default="auto",
    )

    def material(self):
        """The translucent.Material these settings describe, in scene units."""
        import translucent

        k = self.mm_per_unit
        return translucent.Material(
            tuple(x * k for x in self.sigma_a), tuple(x * k for x in self.sigma_s), g=self.g, eta=self.eta
        )


def register():
    bpy.utils.register_class(TranslucentMaterialSettings)
    bpy.types.Material.translucent = bpy.props.PointerProperty(type=TranslucentMaterialSettings)


def unregister():
    del bpy.types.Material.translucent
    bpy.utils.unregister_class(TranslucentMaterialSettings)
