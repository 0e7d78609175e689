"""Mapping between (sigma_a, sigma_s, g, eta) and the inputs of Cycles' Principled BSDF with
random-walk subsurface scattering, as Blender 5.0.1 turns them into a medium.

What Cycles does (intern/cycles/kernel/closure/bssrdf.h and
intern/cycles/kernel/integrator/subsurface_random_walk.h):

- `bssrdf_setup`: anisotropy clamped to [0, 0.9], IOR to [1.01, 3.8].
- `bssrdf_setup_radius`, method "Random Walk": d = radius * scale / (4 pi) per channel.
- `subsurface_random_walk_remap(albedo, d, g)`: the single-scattering albedo alpha is a fit of
  the surface albedo (Chiang et al. 2016, with Wrenninge et al.'s anisotropy terms A..F below),
  clamped to [0, 0.999999]; sigma_t = (1 / d) / (1 - g).
- `subsurface_random_walk_coefficients`: alpha below 0.2 is raised to 0.2 and the path's
  throughput scaled by alpha / 0.2 instead, so such channels are not the same medium.

Hence sigma_s = alpha sigma_t and sigma_a = (1 - alpha) sigma_t, in 1 / scene unit when the
radius is in scene units. `to_principled` inverts this per channel (alpha is increasing in the
albedo: bisection); `from_principled` is the forward map. Both maps and the clamps live in the
native core; this module adapts them and holds the bpy helpers (which import bpy when called).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import _native

# Cycles' clamps, stated once in the native core (`optics::principled`).
MIN_ALPHA, MAX_ALPHA = _native.CYCLES_CLAMPS["albedo"]  # below MIN_ALPHA throughput scaling stands in
G_RANGE = tuple(_native.CYCLES_CLAMPS["anisotropy"])  # bssrdf_setup's anisotropy clamp
IOR_RANGE = tuple(_native.CYCLES_CLAMPS["ior"])  # bssrdf_setup's IOR clamp


def single_scattering_albedo(albedo: float, g: float) -> float:
    """Cycles' `subsurface_random_walk_remap`: the single-scattering albedo for a surface
    albedo (Base Color channel) and anisotropy g, before the clamp (the native module's)."""
    return _native.single_scattering_albedo(float(albedo), float(g))


@dataclass
class Principled:
    """Principled BSDF inputs (subsurface method "Random Walk") that change Cycles' diffuse
    answer; Blender's names and defaults."""

    base_color: tuple[float, float, float]
    radius: tuple[float, float, float]  # Subsurface Radius, multiplied by `scale`
    scale: float  # Subsurface Scale [scene units]
    anisotropy: float
    ior: float
    # False where a channel's single-scattering albedo is below Cycles' 0.2, which Cycles
    # renders by scaling the throughput instead (not the same medium).
    exact: bool = True
    roughness: float = 0.5
    subsurface_weight: float = 1.0
    metallic: float = 0.0
    transmission: float = 0.0
    specular_ior_level: float = 0.5

    def material(self):
        """The translucent.Material Cycles renders for these inputs (medium and layers)."""
        return _native.Material.from_principled(
            self.base_color, self.radius, self.scale, anisotropy=self.anisotropy, ior=self.ior,
            roughness=self.roughness, subsurface_weight=self.subsurface_weight, metallic=self.metallic,
            transmission=self.transmission, specular_ior_level=self.specular_ior_level,
        )


def _check_rgb(name: str, v) -> tuple[float, float, float]:
    t = tuple(float(x) for x in (v if np.ndim(v) else (v, v, v)))
    if len(t) != 3 or not all(math.isfinite(x) and x >= 0.0 for x in t):
        raise ValueError(f"{name} must be three finite values >= 0, got {v!r}")
    return t


def from_principled(base_color, radius, scale: float, anisotropy: float, ior: float):
    """The (sigma_a, sigma_s, g, eta) Cycles simulates for these Principled inputs, sigma in
    1 / (the unit of radius * scale). Cycles' own clamps of g and IOR apply (the walk's IOR is
    clamped to [1.01, 3.8]; eta here is that clamp of `ior`)."""
    m = _native.Material.from_principled(
        _check_rgb("base_color", base_color), _check_rgb("radius", radius), float(scale),
        anisotropy=float(anisotropy), ior=min(max(float(ior), 1.0), 5.0),
    )
    eta = min(max(float(ior), IOR_RANGE[0]), IOR_RANGE[1])
    return m.sigma_a, m.sigma_s, m.g, eta


def to_principled(sigma_a, sigma_s, g: float = 0.0, eta: float = 1.3) -> Principled:
    """Principled inputs for which Cycles simulates sigma_a, sigma_s [1 / scene unit], g, eta
    (the native `principled_for_medium`: bisection on the increasing remap per channel).
    Raises ValueError for what Cycles cannot represent: g outside [0, 0.9], eta outside
    [1.01, 3.8], a channel with no scattering or a single-scattering albedo above 0.999999."""
    sigma_a, sigma_s = _check_rgb("sigma_a", sigma_a), _check_rgb("sigma_s", sigma_s)
    colour, radius, scale, exact = _native.principled_for_medium(sigma_a, sigma_s, float(g), float(eta))
    return Principled(tuple(colour), tuple(radius), scale, g, eta, exact)


def principled_for(material) -> Principled:
    """The Principled inputs Cycles renders `material` with: its medium through `to_principled`
    and its layers (Roughness, Subsurface Weight, Metallic, Transmission)."""
    p = to_principled(material.sigma_a, material.sigma_s, material.g, material.eta)
    p.roughness = material.roughness
    p.subsurface_weight = material.subsurface_weight
    p.metallic = material.metallic
    p.transmission = material.transmission
    if material.subsurface_weight < 1.0:
        # The diffuse lobe's colour is the Base Color: only the medium's own is available.
        if any(abs(a - b) > 1e-6 for a, b in zip(material.base_color, p.base_color)):
            raise ValueError("a diffuse lobe needs the Base Color the medium maps to; build the material "
                             "with Material.from_principled")
    return p


# Principled inputs that change Cycles' diffuse answer, by Blender's socket names.
_SOCKETS = {
    "roughness": "Roughness",
    "subsurface_weight": "Subsurface Weight",
    "metallic": "Metallic",
    "transmission": "Transmission Weight",
    "specular_ior_level": "Specular IOR Level",
}


def apply_to_principled(node, p: Principled) -> None:
    """Set a Principled BSDF node's inputs to `p` (method "Random Walk")."""
    node.subsurface_method = "RANDOM_WALK"
    node.inputs["Base Color"].default_value = (*p.base_color, 1.0)
    node.inputs["Subsurface Radius"].default_value = p.radius
    node.inputs["Subsurface Scale"].default_value = p.scale
    node.inputs["Subsurface Anisotropy"].default_value = p.anisotropy
    node.inputs["IOR"].default_value = p.ior
    for field, socket in _SOCKETS.items():
        node.inputs[socket].default_value = getattr(p, field)


# The colour Cycles gives a surface with no material, and the default viewport colour.
DEFAULT_SURFACE = (0.8, 0.8, 0.8)


def diffuse_albedo(material) -> tuple[float, float, float]:
    """The albedo one diffuse bounce off a surface of `material` (a bpy Material, or None)
    takes: of the node the Material Output's Surface takes, a Principled BSDF's Base Color x
    (1 - Metallic) x (1 - Transmission Weight) (what its diffuse and subsurface lobes reflect
    in all; unconnected values), a Diffuse BSDF's Color, an Emission's 0; no material: Cycles' default surface
    (grey 0.8); any other shader, or a connected colour: the material's viewport colour
    (Viewport Display), an approximation. Specular, sheen and coat layers are left out.
    Clamped to [0, 1]."""
    if material is None:
        return DEFAULT_SURFACE
    fallback = tuple(float(x) for x in material.diffuse_color[:3])
    # Blender 5 always has nodes (use_nodes is deprecated); a tree-less material reads its
    # viewport colour.
    tree = material.node_tree
    out = None if tree is None else next((n for n in tree.nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output),
                                         None)
    link = None if out is None or not out.inputs["Surface"].is_linked else out.inputs["Surface"].links[0]
    node = None if link is None else link.from_node
    colour = fallback
    if node is not None and node.type == "BSDF_PRINCIPLED" and not node.inputs["Base Color"].is_linked:
        k = (1.0 - node.inputs["Metallic"].default_value) * (1.0 - node.inputs["Transmission Weight"].default_value)
        colour = tuple(float(x) * k for x in node.inputs["Base Color"].default_value[:3])
    elif node is not None and node.type == "BSDF_DIFFUSE" and not node.inputs["Color"].is_linked:
        colour = tuple(float(x) for x in node.inputs["Color"].default_value[:3])
    elif node is not None and node.type == "EMISSION":
        colour = (0.0, 0.0, 0.0)  # it emits and reflects nothing
    return tuple(min(max(x, 0.0), 1.0) for x in colour)


def emits(material) -> bool:
    """Whether Cycles sees light leave a surface of `material` (a bpy Material, or None): an
    Emission node, or a Principled BSDF with an Emission Strength above 0 (or either input
    connected) and a colour that is not black, anywhere upstream of the active Material
    Output's Surface."""
    tree = None if material is None else material.node_tree
    out = None if tree is None else next((n for n in tree.nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output),
                                         None)
    if out is None:
        return False
    seen, todo = set(), [out]
    while todo:
        node = todo.pop()
        if node.name in seen:
            continue
        seen.add(node.name)
        sockets = {"EMISSION": ("Color", "Strength"), "BSDF_PRINCIPLED": ("Emission Color", "Emission Strength")}
        if node.type in sockets:
            colour, strength = (node.inputs[k] for k in sockets[node.type])
            bright = colour.is_linked or max(colour.default_value[:3]) > 0.0
            if bright and (strength.is_linked or strength.default_value > 0.0):
                return True
        inputs = [out.inputs["Surface"]] if node is out else node.inputs
        todo.extend(link.from_node for i in inputs for link in i.links)
    return False


def emission(material) -> tuple[float, float, float] | None:
    """The radiance a surface of `material` emits, per channel, where it is one constant: the
    node the active Material Output's Surface takes is an Emission node or a Principled BSDF
    with its colour and strength unconnected (Color x Strength, Emission Color x Emission
    Strength: Blender's manual, a Strength of 1 shows the Color itself, so it is the radiance).
    None where it emits nothing or not a constant (a mix, a texture: `emits` still says)."""
    tree = None if material is None else material.node_tree
    out = None if tree is None else next((n for n in tree.nodes if n.type == "OUTPUT_MATERIAL" and n.is_active_output),
                                         None)
    if out is None or not out.inputs["Surface"].is_linked:
        return None
    node = out.inputs["Surface"].links[0].from_node
    names = {"EMISSION": ("Color", "Strength"), "BSDF_PRINCIPLED": ("Emission Color", "Emission Strength")}
    if node.type not in names:
        return None
    colour, strength = (node.inputs[k] for k in names[node.type])
    if colour.is_linked or strength.is_linked:
        return None
    radiance = tuple(max(float(c), 0.0) * float(strength.default_value) for c in colour.default_value[:3])
    return radiance if max(radiance) > 0.0 else None


def read_principled(node) -> Principled:
    """Every input of a Principled BSDF node that changes Cycles' subsurface answer
    (unconnected values)."""
    i = node.inputs
    return Principled(
        tuple(i["Base Color"].default_value)[:3],
        tuple(i["Subsurface Radius"].default_value),
        float(i["Subsurface Scale"].default_value),
        float(i["Subsurface Anisotropy"].default_value),
        float(i["IOR"].default_value),
        **{field: float(i[socket].default_value) for field, socket in _SOCKETS.items()},
    )


def make_volume_material(name: str, sigma_a, sigma_s, g: float, eta: float):
    """The second reference: a homogeneous volume (Volume Scatter + Volume Absorption, density
    in 1 / scene unit) inside a smooth refractive boundary of IOR eta (Refraction BSDF,
    roughness 0). Returns the new bpy material."""
    import bpy

    sigma_a, sigma_s = _check_rgb("sigma_a", sigma_a), _check_rgb("sigma_s", sigma_s)
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # Blender < 5.0 (5.0 always has nodes; use_nodes is deprecated)
        mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    out = nodes.new("ShaderNodeOutputMaterial")
    glass = nodes.new("ShaderNodeBsdfRefraction")
    glass.inputs["IOR"].default_value = eta
    glass.inputs["Roughness"].default_value = 0.0
    links.new(glass.outputs[0], out.inputs["Surface"])
    # Per-channel coefficients: colour = sigma / density with density the largest channel.
    scatter, absorb = nodes.new("ShaderNodeVolumeScatter"), nodes.new("ShaderNodeVolumeAbsorption")
    ks, ka = max(sigma_s), max(sigma_a)
    scatter.inputs["Color"].default_value = (*[s / ks if ks else 0.0 for s in sigma_s], 1.0)
    scatter.inputs["Density"].default_value = ks
    scatter.inputs["Anisotropy"].default_value = g
    absorb.inputs["Color"].default_value = (*[1.0 - (a / ka if ka else 0.0) for a in sigma_a], 1.0)
    absorb.inputs["Density"].default_value = ka
    add = nodes.new("ShaderNodeAddShader")
    links.new(scatter.outputs[0], add.inputs[0])
    links.new(absorb.outputs[0], add.inputs[1])
    links.new(add.outputs[0], out.inputs["Volume"])
    return mat
