"""Settings of the preview, stored on the material (they save with the .blend file).
Coefficients are shown per millimetre (Jensen's table units); `mm_per_unit` converts.

Where the medium comes from (`source`): the material's own Principled BSDF, followed as the
artist edits it (every input that changes Cycles' subsurface answer: Base Color, Subsurface
Weight, Radius, Scale, Anisotropy, IOR, Specular IOR Level, Roughness, Metallic, Transmission),
or custom coefficients and Jensen's presets. The profile (`profile`): Cycles' random walk, what
a Cycles render shows (the default), or Jensen's dipole, the papers' model."""

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
    self["source"] = 1  # Custom: a preset is the artist's choice over the node
    _live_edit(self, context)


def _coefficient_edit(self, context):
    """An explicit coefficient edit means custom coefficients from now on."""
    if self.source == "PRINCIPLED":
        self["source"] = 1
    session.edit(self.id_data)


def _live_edit(self, context):
    session.edit(self.id_data)


def principled_node(mat):
    tree = getattr(mat, "node_tree", None)
    if tree is None:
        return None
    return next((n for n in tree.nodes if n.type == "BSDF_PRINCIPLED"), None)


def principled_inputs(mat):
    """The Principled BSDF inputs Cycles' subsurface answer depends on (`cycles.Principled`),
    or None when the material has no Principled BSDF."""
    from translucent import cycles

    node = principled_node(mat)
    return None if node is None else cycles.read_principled(node)


def read_from_principled(settings) -> bool:
    """Start from the material's own Principled BSDF: its subsurface inputs mapped to the
    medium Cycles would simulate, shown in the coefficient fields; from then on the preview
    follows the node (`source`). Returns whether it did."""
    node = principled_node(settings.id_data)
    if node is None or node.inputs["Subsurface Weight"].default_value <= 0.0:
        return False
    try:
        show_medium(settings, principled_inputs(settings.id_data).material())
    except ValueError:
        return False
    settings["preset"] = 0  # Custom
    settings["source"] = 0  # Principled BSDF
    return True


def show_medium(settings, m) -> None:
    """Show the medium `m` (per scene unit) in the coefficient fields (per mm), without
    triggering their edit callbacks; only what differs is written (no update loops)."""
    k = settings.mm_per_unit
    values = {"sigma_a": tuple(x / k for x in m.sigma_a), "sigma_s": tuple(x / k for x in m.sigma_s),
              "g": m.g, "eta": min(m.eta, 2.5)}
    for key, v in values.items():
        old = getattr(settings, key)
        same = all(abs(a - b) <= 1e-7 * max(abs(b), 1e-12) for a, b in zip(old, v)) if isinstance(v, tuple) else (
            abs(old - v) <= 1e-7)
        if not same:
            settings[key] = v


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
        if self.follow_scene:
            session.follow_again(mat)  # what changed while the preview was off
    elif not self.enabled:
        viewport.restore(objects or session.objects_with(mat))


def _follow_toggle(self, context):
    if self.follow_scene and self.enabled:
        session.follow_again(self.id_data)


class TranslucentMaterialSettings(bpy.types.PropertyGroup):
    enabled: BoolProperty(
        name="Preview", description="Show a subsurface-scattering preview of this material", default=False, update=_toggle
    )
    initialised: BoolProperty(
        name="Initialised", description="Settings were read from the material once", default=False,
        options={"HIDDEN"},
    )
    source: EnumProperty(
        name="Medium",
        items=[("PRINCIPLED", "Principled BSDF", "Follow the material's Principled BSDF as it is edited (Cycles' mapping)"),
               ("CUSTOM", "Custom", "The coefficients below, or one of Jensen's measured presets")],
        default="CUSTOM", update=_live_edit,
    )
    profile: EnumProperty(
        name="Profile",
        items=[("CYCLES", "Cycles Random Walk", "Cycles' random walk tabulated, with the Principled layers: "
                "what a Cycles render shows"),
               ("DIPOLE", "Dipole", "Jensen's dipole (Jensen 2001), the model of the papers the methods follow")],
        default="CYCLES", update=_live_edit,
    )
    preset: EnumProperty(name="Preset", items=_preset_items, update=_apply_preset)
    sigma_a: FloatVectorProperty(
        name="Absorption", description="sigma_a per channel [1/mm]", size=3, min=0.0, soft_max=10.0,
        default=(0.0021, 0.0041, 0.0071), precision=4, update=_coefficient_edit,
    )
    sigma_s: FloatVectorProperty(
        name="Scattering", description="sigma_s per channel [1/mm]", size=3, min=0.0, soft_max=50.0,
        default=(2.19, 2.62, 3.00), precision=3, update=_coefficient_edit,
    )
    g: FloatProperty(name="Anisotropy g", description="Phase-function mean cosine (Cycles: 0 to 0.9)", min=-0.99,
                     max=0.99, default=0.0, update=_coefficient_edit)
    eta: FloatProperty(name="IOR", description="Relative index of refraction (the dipole needs a new precompute "
                       "when it changes; Cycles' profile does not)", min=1.0, max=2.5, default=1.3,
                       update=_coefficient_edit)
    mm_per_unit: FloatProperty(name="mm per unit", description="Millimetres per scene unit (1000 for metres)", min=1e-6, default=1000.0)
    coefficients: IntProperty(name="Basis size", description="Coefficients of the piecewise polynomial basis (Xu 2007)", min=4, max=128, default=32)
    degree: EnumProperty(name="Degree", items=[("1", "Linear", "C0 piecewise linear"), ("2", "Quadratic", "C1 piecewise quadratic")], default="1")
    auto_refresh: BoolProperty(
        name="Auto refresh",
        description="When an edit leaves the range the basis was chosen for (the error estimate says so), "
        "precompute again in the background",
        default=True,
    )
    method: EnumProperty(
        name="Method",
        items=[("AUTO", "Auto", "Choose by what changed: PRT for material edits and lights, the hierarchy for "
                "deforming or animated meshes (PRT while translucent has no hierarchy)"),
               ("PRT", "PRT", "Precomputed radiance transfer (Xu 2007): live material edits; a moved light or a "
                "deformation precomputes again in the background"),
               ("HIERARCHY", "Hierarchy", "Hierarchical boundary elements (Mertens 2003): deforming scenes, "
                "nothing precomputed that a deformation invalidates (needs translucent.Hierarchy; PRT until then)")],
        default="AUTO",
    )
    follow_scene: BoolProperty(
        name="Follow scene",
        description="When a previewed object deforms (armature, shape keys, modifiers, edit mode, timeline) or "
        "a light or the world changes, refresh the preview in the background; the old preview stays until then",
        default=True, update=_follow_toggle,
    )
    backend: EnumProperty(
        name="Device",
        items=[("auto", "Auto", "A GPU if there is one, else the CPU"), ("gpu", "GPU", "wgpu compute"), ("cpu", "CPU", "rayon")],
        default="auto",
    )

    def material(self):
        """The translucent.Material these settings describe, in scene units: the Principled
        BSDF's medium and layers when following it, else the coefficients."""
        import translucent

        if self.source == "PRINCIPLED":
            p = principled_inputs(self.id_data)
            if p is not None:
                return p.material()
        k = self.mm_per_unit
        return translucent.Material(
            tuple(x * k for x in self.sigma_a), tuple(x * k for x in self.sigma_s), g=self.g, eta=self.eta
        )

    def profile_name(self) -> str:
        return self.profile.lower()


def register():
    bpy.utils.register_class(TranslucentMaterialSettings)
    bpy.types.Material.translucent = bpy.props.PointerProperty(type=TranslucentMaterialSettings)


def unregister():
    del bpy.types.Material.translucent
    bpy.utils.unregister_class(TranslucentMaterialSettings)
