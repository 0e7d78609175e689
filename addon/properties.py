"""Settings of the preview, stored on the material (they save with the .blend file).
Coefficients are shown per millimetre (Jensen's table units); `mm_per_unit` converts.

Where the medium comes from (`source`): the material's own Principled BSDF, followed as the
artist edits it (every input that changes Cycles' subsurface answer: Base Color, Subsurface
Weight, Radius, Scale, Anisotropy, IOR, Specular IOR Level, Roughness, Metallic, Transmission),
or custom coefficients and Jensen's presets. The profile (`profile`): Cycles' random walk, what
a Cycles render shows (the default), Jensen's dipole, the papers' model, or Donner and Jensen's
multipole, which reads the medium's depth (`thickness_mm`, 0 for a half-space) and a thin layer
of one of Jensen's presets over it (`top_layer`, `top_thickness_mm`)."""

from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty

from . import edits, follow, splat_view
from .principled import principled_inputs, read_from_principled


def _preset_names() -> list[str]:
    """Jensen 2001's measured materials, none where the native module is missing."""
    try:
        import translucent

        return translucent.Material.preset_names()
    except ImportError:
        return []


def _preset_items(self, context):
    return [("CUSTOM", "Custom", "Coefficients as set below")] + [
        (n.upper(), n.capitalize(), f"Jensen 2001 measured {n}") for n in _preset_names()
    ]


def _top_layer_items(self, context):
    return [("NONE", "None", "No layer over the medium")] + [
        (n.upper(), n.capitalize(), f"A layer of Jensen 2001 measured {n}") for n in _preset_names()
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
    edits.edit(self.id_data)


def _live_edit(self, context):
    edits.edit(self.id_data)


def _toggle(self, context):
    """Turning the preview on the first time starts from the material's Principled BSDF;
    turning it off puts the viewports and active colour attributes back; on again shows the
    transport if there is one."""
    mat = self.id_data
    if self.enabled and not self.initialised:
        self["initialised"] = True
        read_from_principled(self)
    if not self.enabled:
        edits.preview_off(mat)
    elif edits.preview_on(mat) and self.follow_scene:
        follow.follow_again(mat)  # what changed while the preview was off


def _follow_toggle(self, context):
    if self.follow_scene and self.enabled:
        follow.follow_again(self.id_data)


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
               ("DIPOLE", "Dipole", "Jensen's dipole (Jensen 2001), the model of the papers the methods follow"),
               ("MULTIPOLE", "Multipole", "Donner and Jensen 2005: the medium as a slab of the Thickness below, "
                "under an optional thin top layer (Shah 2009 Fig. 11)")],
        default="CYCLES", update=_live_edit,
    )
    thickness_mm: FloatProperty(
        name="Thickness", description="Depth of the medium [mm] for the multipole profile; 0: a half-space "
        "(the dipole's assumption)", min=0.0, soft_max=100.0, default=0.0, precision=2, update=_live_edit,
    )
    top_layer: EnumProperty(
        name="Top layer", description="A thin layer of one of Jensen's measured media over the medium "
        "(multipole profile)", items=_top_layer_items, update=_live_edit,
    )
    top_thickness_mm: FloatProperty(
        name="Top thickness", description="Depth of the top layer [mm]; at least its source depth 1/sigma_t' "
        "(diffusion does not hold in thinner layers)", min=1e-4, soft_max=10.0, default=1.0, precision=3,
        update=_live_edit,
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
        items=[("AUTO", "Auto", "Choose by what changed: PRT for material edits, lights (relit, no walk traced) "
                "and poses (its walks carried to the pose at once, then traced on it); the hierarchy where it "
                "already holds the transport"),
               ("PRT", "PRT", "Precomputed radiance transfer (Xu 2007): live material edits; a moved light is "
                "relit and a pose carried at once, then refined in the background"),
               ("HIERARCHY", "Hierarchy", "Hierarchical boundary elements (Mertens 2003): deforming scenes, "
                "nothing precomputed that a deformation invalidates"),
               ("SPLAT", "Splatting", "Image-space splatting (Shah 2009) at the vertices: nothing precomputed, so "
                "every edit, light move or pose splats the scene again in the background (seconds); its "
                "Threshold, Light grid and Splats on are the Splatting image's")],
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

        m = None
        if self.source == "PRINCIPLED":
            p = principled_inputs(self.id_data)
            if p is not None:
                m = p.material()
        if m is None:
            k = self.mm_per_unit
            m = translucent.Material(
                tuple(x * k for x in self.sigma_a), tuple(x * k for x in self.sigma_s), g=self.g, eta=self.eta
            )
        return self.stacked(m)

    def stacked(self, m):
        """`m` with the multipole's depth and top layer (scene units), when that profile is chosen."""
        if self.profile != "MULTIPOLE" or (self.thickness_mm <= 0.0 and self.top_layer == "NONE"):
            return m
        import math

        import translucent

        unit = self.mm_per_unit
        thickness = self.thickness_mm / unit if self.thickness_mm > 0.0 else math.inf
        if self.top_layer == "NONE":
            return m.with_stack(thickness)
        top = translucent.Material.preset(self.top_layer.lower(), mm_per_unit=unit)
        return m.with_stack(thickness, top=top, top_thickness=self.top_thickness_mm / unit)

    def profile_name(self) -> str:
        return self.profile.lower()


def _show_toggle(self, context):
    splat_view.show_toggle(self, context)


def _splat_changed(self, context):
    splat_view.settings_changed(self, context)


class TranslucentSplatSettings(bpy.types.PropertyGroup):
    """The splatting image's settings (Shah 2009), stored on the scene: one image for every
    previewed material in it."""

    show_in_viewport: BoolProperty(
        name="Show in viewport",
        description="Draw the splatting's image over the 3D viewports, rendered again by itself when the view, a "
        "light, a previewed mesh or a material changes",
        default=False, update=_show_toggle,
    )
    eps: FloatProperty(name="Threshold", description="Shah 2009 eqs. 4-5: the share of each splat's light left "
                       "beyond its radius, and Weber's fraction for the overlap", min=1e-4, max=0.5, default=0.01,
                       precision=4, update=_splat_changed)
    max_grid: IntProperty(name="Light grid", description="The largest side of each light's view grid (eq. 5's "
                          "grid is cut to it; more is finer and slower)", min=16, max=4096, default=1024,
                          update=_splat_changed)
    backend: EnumProperty(
        name="Splats on", description="Where the splats are drawn into the image (Shah 2009's pass 3)",
        items=[("AUTO", "Auto", "A hardware GPU that blends float-32 images if there is one, else the CPU"),
               ("GPU", "GPU", "Any Vulkan adapter, Mesa's software lavapipe included (slower than the CPU there)"),
               ("CPU", "CPU", "The gather on the CPU's cores")],
        default="AUTO", update=_splat_changed,
    )
    max_side: IntProperty(name="Viewport size", description="The largest side in pixels of the image rendered for "
                          "a viewport (the CPU render takes seconds at 800 x 600)", min=16, max=4096, default=320)


def register():
    bpy.utils.register_class(TranslucentMaterialSettings)
    bpy.types.Material.translucent = bpy.props.PointerProperty(type=TranslucentMaterialSettings)
    bpy.utils.register_class(TranslucentSplatSettings)
    bpy.types.Scene.translucent_splat = bpy.props.PointerProperty(type=TranslucentSplatSettings)


def unregister():
    del bpy.types.Scene.translucent_splat
    bpy.utils.unregister_class(TranslucentSplatSettings)
    del bpy.types.Material.translucent
    bpy.utils.unregister_class(TranslucentMaterialSettings)
