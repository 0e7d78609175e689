"""The transport of each previewed material, held in memory (never saved: a reloaded file asks
for a new precompute), and the edit path: refit + dot product + write-back."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import bpy
import numpy as np

from . import export, writeback


@dataclass
class Session:
    prt: object  # translucent.Prt
    info: export.ExportInfo
    objects: list[str]
    fingerprint: str
    eta: float
    last_error: list[float] = field(default_factory=list)
    last_seconds: float = 0.0
    not_shown: list[str] = field(default_factory=list)


# material name -> Session
SESSIONS: dict[str, Session] = {}
# material name -> running precompute job
JOBS: dict[str, "Job"] = {}


def objects_with(material: bpy.types.Material, scene: bpy.types.Scene | None = None) -> list[bpy.types.Object]:
    """Mesh objects of the scene whose material slots hold `material`: the only ones exported."""
    scene = scene or bpy.context.scene
    return [o for o in scene.objects if o.type == "MESH" and any(s.material == material for s in o.material_slots)]


def fingerprint(objects, bl_scene) -> str:
    """What the transport depends on: evaluated geometry, lights, world. Cheap to compare."""
    import hashlib

    h = hashlib.sha256()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for o in objects:
        p, t, _ = export.evaluated_mesh_arrays(o, depsgraph)
        h.update(p.tobytes())
        h.update(t.tobytes())
    for o in bl_scene.objects:
        if o.type == "LIGHT":
            h.update(np.array(o.matrix_world, np.float32).tobytes())
            d = o.data
            h.update(repr((d.type, d.energy, tuple(d.color), getattr(d, "spot_size", 0), getattr(d, "size", 0), o.hide_render)).encode())
    w = bl_scene.world
    if w is not None:
        h.update(repr(tuple(w.color)).encode())
        if w.node_tree is not None:
            for n in w.node_tree.nodes:
                for i in n.inputs:
                    if hasattr(i, "default_value"):
                        try:
                            h.update(repr(tuple(i.default_value)).encode())
                        except TypeError:
                            h.update(repr(i.default_value).encode())
    return h.hexdigest()


class Job:
    """A precompute on a worker thread that never touches bpy; the operator polls it."""

    def __init__(self, scene, materials, **kwargs):
        self.progress = 0.0
        self.cancel = False
        self.result = None
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(scene, materials, kwargs), daemon=True)

    def _tick(self, f: float) -> bool:
        self.progress = f
        return not self.cancel

    def _run(self, scene, materials, kwargs):
        import translucent

        try:
            self.result = translucent.Prt(scene, materials, progress=self._tick, **kwargs)
        except BaseException as e:  # reported to the user by the operator
            self.error = e

    def start(self):
        self._thread.start()

    def run_here(self):
        self._thread.run()

    @property
    def done(self) -> bool:
        return not self._thread.is_alive() and (self.result is not None or self.error is not None)


def start(material: bpy.types.Material, bl_scene=None) -> tuple[Job, list[str], export.ExportInfo, str]:
    """Exports what the material needs and creates (but does not start) its precompute job."""
    bl_scene = bl_scene or bpy.context.scene
    objects = objects_with(material, bl_scene)
    if not objects:
        raise ValueError(f"no mesh object uses material {material.name!r}")
    scene, info = export.export_scene(objects, bl_scene=bl_scene)
    s = material.translucent
    job = Job(scene, [s.material()], coefficients=s.coefficients, degree=int(s.degree), backend=s.backend)
    return job, [o.name for o in objects], info, fingerprint(objects, bl_scene)


def finish(material: bpy.types.Material, job: Job, objects, info, fp) -> Session:
    session = Session(job.result, info, objects, fp, material.translucent.eta)
    SESSIONS[material.name] = session
    edit(material)
    return session


def state(material: bpy.types.Material) -> str:
    """'none', 'running', 'stale' or 'ready' for the panel."""
    if material.name in JOBS:
        return "running"
    s = SESSIONS.get(material.name)
    if s is None:
        return "none"
    if abs(s.eta - material.translucent.eta) > 1e-9:
        return "stale"
    objects = [bpy.data.objects.get(n) for n in s.objects]
    if any(o is None for o in objects) or fingerprint(objects, bpy.context.scene) != s.fingerprint:
        return "stale"
    return "ready"


def edit(material: bpy.types.Material) -> None:
    """Refit and re-evaluate the material, and write every object's preview attribute."""
    s = SESSIONS.get(material.name)
    if s is None or not material.translucent.enabled:
        return
    settings = material.translucent
    if abs(s.eta - settings.eta) > 1e-9:
        return  # a new IOR needs a new precompute; the panel says so
    prt = s.prt
    # Radiance leaving along each normal: a view-independent viewport colour.
    colors = prt.radiance(settings.material())
    s.last_error = list(prt.last_eval["error_estimate"])
    s.last_seconds = prt.last_eval["seconds"]
    s.not_shown = []
    for name, values in writeback.split(colors, s.info).items():
        obj = bpy.data.objects.get(name)
        if obj is not None and len(obj.data.vertices) == len(values):
            writeback.write_colors(obj.data, values)
        else:
            # A modifier changed the vertex count: the attribute cannot hold the values.
            s.not_shown.append(name)
