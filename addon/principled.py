"""The material's Principled BSDF, read (never written): the inputs Cycles' subsurface answer
depends on (`translucent.cycles`), and the medium they map to shown in the coefficient fields."""

from __future__ import annotations

import dataclasses


def principled_node(mat):
    """The material's first Principled BSDF node, or None."""
    tree = getattr(mat, "node_tree", None)
    if tree is None:
        return None
    return next((n for n in tree.nodes if n.type == "BSDF_PRINCIPLED"), None)


# The Principled inputs the preview reads (`cycles.read_principled`), by Blender's socket names.
READ = ("Base Color", "Subsurface Radius", "Subsurface Scale", "Subsurface Anisotropy", "IOR", "Roughness",
        "Subsurface Weight", "Metallic", "Transmission Weight", "Specular IOR Level")


def connected_inputs(mat) -> list[str]:
    """The inputs the preview reads that a link drives (an image texture, a colour attribute, a
    procedural), each with the node it comes from. PRT follows a linked Base Color and
    Subsurface Weight per vertex and a linked Radius, Scale and Roughness by their mean
    (`textures`); for the others the preview takes the socket's own value, uniformly, where
    Cycles evaluates the link per point (the panel says so)."""
    node = principled_node(mat)
    if node is None:
        return []
    return [f"{name} ({node.inputs[name].links[0].from_node.bl_label})" for name in READ
            if name in node.inputs and node.inputs[name].is_linked]


# Material name -> {socket: value}: a linked Subsurface Radius, Scale or Roughness read by
# Cycles at the exported vertices and previewed at their mean (`textures.read`), in place of
# the socket's own value while the link stays.
MEANS: dict[str, dict] = {}
_MEAN_FIELDS = {"Subsurface Radius": "radius", "Subsurface Scale": "scale", "Roughness": "roughness"}


def principled_inputs(mat):
    """The Principled BSDF inputs Cycles' subsurface answer depends on (`cycles.Principled`),
    or None when the material has no Principled BSDF. A linked Subsurface Radius, Scale or
    Roughness takes the mean `textures.read` found (`MEANS`) where there is one."""
    from translucent import cycles

    node = principled_node(mat)
    if node is None:
        return None
    p = cycles.read_principled(node)
    means = {_MEAN_FIELDS[k]: v for k, v in MEANS.get(mat.name, {}).items() if node.inputs[k].is_linked}
    return dataclasses.replace(p, **means) if means else p


def principled_key(mat) -> str:
    """The Principled inputs the preview follows, as a string to compare."""
    return repr(principled_inputs(mat))


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


def input_lines(p) -> list[str]:
    """The Principled inputs `p` (`cycles.Principled`) as the panel shows them, two lines."""
    return [f"Radius {', '.join(f'{r:.3g}' for r in p.radius)} x Scale {p.scale:.3g}, "
            f"Anisotropy {p.anisotropy:.2f}, IOR {p.ior:.3g}",
            f"Subsurface Weight {p.subsurface_weight:.2f}, Roughness {p.roughness:.2f}, "
            f"Metallic {p.metallic:.2f}, Transmission {p.transmission:.2f}"]
