"""The session registry: each previewed material's transport and what the add-on knows about it,
held in memory (never saved: a reloaded file asks for a new precompute), and its state."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import bpy

from . import export


@dataclass
class Session:
    transport: object  # what the method built: a translucent.Prt, Hierarchy or Splat
    info: export.ExportInfo
    objects: list[str]
    # export.lighting_keys at the precompute: what each light and the world were.
    lighting: dict
    eta: float
    # "cycles", "dipole" or "multipole": the profile the transport was precomputed for.
    profile: str = "cycles"
    # The Principled inputs last shown (when following the node), to notice edits.
    principled_key: str = ""
    # Why the last edit was not shown (a Principled input Cycles would not take, ...).
    edit_message: str = ""
    # The method's own `last_eval` at the last edit, as it reported it (None: no edit yet).
    last_eval: dict | None = None
    # Its error estimate per channel (relative); None when the method computed none (the
    # panel then says so and never shows a number for it).
    last_error: list[float] | None = None
    last_seconds: float = 0.0
    # Objects whose preview could not be written, each "NAME: why" (the panel shows them).
    not_shown: list[str] = field(default_factory=list)
    # Objects whose modifiers change the vertex count: for each original vertex, the evaluated
    # vertex nearest to it (the modifier stack then interpolates the attribute for display).
    remap: dict = field(default_factory=dict)
    # The material (sigma_a, sigma_s, g) the basis and samples were chosen for.
    chosen_for: tuple = ()
    refresh_advised: bool = False
    refresh_message: str = ""
    # "prt", "hierarchy" or "splat": what built the transport, and why it is not the method asked for.
    method: str = "prt"
    method_message: str = ""
    # Objects whose evaluated geometry differs from the transport's: name -> "deformed",
    # "topology" (vertex count) or "removed". Kept by the follow check, read by the panel.
    deformed: dict = field(default_factory=dict)
    # What differs from the transport ("" when nothing): the panel's "stale" and its reason.
    changed: str = ""
    # Mesh objects that took or lost the material since ("" when none), in words.
    members_changed: str = ""
    # Occluders moved, deformed, added or removed since ("occluder Box changed"; "" when none).
    occluders_changed: str = ""
    # The lights' layers being made on a worker thread after a PRT precompute or update
    # (`jobs.LayersPrep`; None headless or for the other methods).
    layers: object = None
    # The hierarchy a dragged light is followed with, built beside a PRT transport with walks
    # (`drag.DragPrep`; None headless, for the other methods and the dipole).
    drag: object = None
    # What following the scene is doing ("refreshing: light Key changed", ...).
    follow_message: str = ""
    # The viewport's eye point the preview is drawn toward (world space), when the transport
    # holds single scattering (view dependent, Xu 2007 eq. 5); None: along each normal.
    eye: tuple | None = None
    # The Base Color per exported vertex where a link drives it (`textures`), None where it is
    # uniform; the node tree's key it was baked for; and the panel's line about it.
    base_color: object = None
    # The Subsurface Weight per exported vertex where a link drives it (Cycles' profile), else None.
    subsurface_weight: object = None
    # A uniform material beside other materials' faces: their albedo per exported vertex, NaN
    # rows for the previewed vertices (`textures.Reading.others`), else None.
    others: object = None
    texture_key: str = ""
    texture_message: str = ""
    # Method = Splatting or Hierarchy (each edit evaluates again, on a worker thread): the last
    # evaluation as (what it was for: `params` and the texture's key, (N, 3) radiance, last_eval).
    evaluated: tuple | None = None
    # The hierarchy's or the splatting's report as that evaluation left it: the panel reads it
    # here, as a worker may hold the transport (its `report` then says it is busy).
    report: dict | None = None


# material name -> Session
SESSIONS: dict[str, Session] = {}
# material name -> running job (`jobs.Job`)
JOBS: dict[str, object] = {}
# material name -> worker thread building Cycles' walk tables for the current material
PREPARING: dict[str, threading.Thread] = {}


def forget() -> None:
    """Drop every session and job (a file was loaded, or the add-on unregistered)."""
    SESSIONS.clear()
    JOBS.clear()


def objects_with(material: bpy.types.Material, scene: bpy.types.Scene | None = None) -> list[bpy.types.Object]:
    """Mesh objects of the scene whose material slots hold `material`: the only ones exported."""
    scene = scene or bpy.context.scene
    return [o for o in scene.objects if o.type == "MESH" and any(s.material == material for s in o.material_slots)]


def params(settings) -> tuple:
    """What the basis and samples were chosen for: the medium and layers, and the profile."""
    try:
        m = settings.material()
    except ValueError:
        return ()
    return (m.sigma_a, m.sigma_s, m.g, m.eta, m.roughness, m.subsurface_weight, m.metallic, m.transmission,
            settings.profile)


def state(material: bpy.types.Material) -> str:
    """'none', 'running', 'stale' or 'ready' for the panel; cheap (it runs on every redraw)."""
    if material.name in JOBS:
        return "running"
    s = SESSIONS.get(material.name)
    if s is None:
        return "none"
    if s.profile != material.translucent.profile_name():
        return "stale"
    if s.profile in ("dipole", "multipole") and abs(s.eta - material.translucent.eta) > 1e-9:
        return "stale"
    # What the follow handler and check found (no mesh is evaluated here: the panel calls this).
    if s.changed or any(bpy.data.objects.get(n) is None for n in s.objects):
        return "stale"
    return "ready"


def view_dependent(s: Session) -> bool:
    """Whether the session's transport holds single scattering (the dipole's L^(1)): only then
    does the preview depend on where the viewer is."""
    return s.method == "prt" and bool(s.transport.report["single_scattering"])
