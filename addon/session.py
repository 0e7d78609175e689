"""The transport of each previewed material, held in memory (never saved: a reloaded file asks
for a new precompute), and the edit path: refit + dot product + write-back."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import bpy
import numpy as np

from . import export, viewport, writeback


@dataclass
class Session:
    prt: object  # translucent.Prt
    info: export.ExportInfo
    objects: list[str]
    fingerprint: str
    eta: float
    # "cycles" or "dipole": the profile the transport was precomputed for.
    profile: str = "cycles"
    # The Principled inputs last shown (when following the node), to notice edits.
    principled_key: str = ""
    # Why the last edit was not shown (a Principled input Cycles would not take, ...).
    edit_message: str = ""
    last_error: list[float] = field(default_factory=list)
    last_seconds: float = 0.0
    not_shown: list[str] = field(default_factory=list)
    # Objects whose modifiers change the vertex count: for each original vertex, the evaluated
    # vertex nearest to it (the modifier stack then interpolates the attribute for display).
    remap: dict = field(default_factory=dict)
    # The material (sigma_a, sigma_s, g) the basis and samples were chosen for.
    chosen_for: tuple = ()
    refresh_advised: bool = False
    refresh_message: str = ""


# material name -> Session
SESSIONS: dict[str, Session] = {}
# material name -> running precompute job
JOBS: dict[str, "Job"] = {}
# material name -> worker thread building Cycles' walk tables for the current material
PREPARING: dict[str, threading.Thread] = {}


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


def nearest_original_vertices(objects: list[str], info: export.ExportInfo) -> dict[str, np.ndarray]:
    """For each object whose evaluated mesh has a different vertex count from its own mesh (a
    Subdivision Surface, a Decimate...), the index of the evaluated vertex nearest to each of
    its original vertices (world space, Blender's own kd-tree). Writing those values on the
    original vertices lets the modifier stack interpolate the preview for display."""
    from mathutils import Matrix, kdtree

    depsgraph = bpy.context.evaluated_depsgraph_get()
    out = {}
    for r in info.objects:
        obj = bpy.data.objects.get(r.name)
        if obj is None or r.name not in objects or len(obj.data.vertices) == r.count:
            continue
        evaluated, _, _ = export.evaluated_mesh_arrays(obj, depsgraph)
        tree = kdtree.KDTree(len(evaluated))
        for i, p in enumerate(evaluated):
            tree.insert(p.tolist(), i)
        tree.balance()
        co = np.empty(len(obj.data.vertices) * 3, np.float32)
        obj.data.vertices.foreach_get("co", co)
        m = np.array(Matrix(obj.matrix_world), dtype=np.float64)
        world = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
        out[r.name] = np.array([tree.find(p.tolist())[1] for p in world], dtype=np.int64)
    return out


def _params(settings) -> tuple:
    """What the basis and samples were chosen for: the medium and layers, and the profile."""
    try:
        m = settings.material()
    except ValueError:
        return ()
    return (m.sigma_a, m.sigma_s, m.g, m.eta, m.roughness, m.subsurface_weight, m.metallic, m.transmission,
            settings.profile)


def start(material: bpy.types.Material, bl_scene=None) -> tuple[Job, list[str], export.ExportInfo, str]:
    """Exports what the material needs and creates (but does not start) its precompute job."""
    bl_scene = bl_scene or bpy.context.scene
    objects = objects_with(material, bl_scene)
    if not objects:
        raise ValueError(f"no mesh object uses material {material.name!r}")
    scene, info = export.export_scene(objects, bl_scene=bl_scene)
    info.skipped_objects = [o.name for o in bl_scene.objects if o.type == "MESH" and o not in objects]
    s = material.translucent
    job = Job(scene, [s.material()], coefficients=s.coefficients, degree=int(s.degree), backend=s.backend,
              profile=s.profile_name())
    job.chosen_for = _params(s)
    job.profile = s.profile_name()
    return job, [o.name for o in objects], info, fingerprint(objects, bl_scene)


def finish(material: bpy.types.Material, job: Job, objects, info, fp) -> Session:
    session = Session(job.result, info, objects, fp, material.translucent.eta, profile=job.profile)
    session.chosen_for = job.chosen_for
    session.remap = nearest_original_vertices(objects, info)
    SESSIONS[material.name] = session
    edit(material)
    viewport.show([o for o in (bpy.data.objects.get(n) for n in objects) if o is not None])
    return session


def summary(sess: Session) -> str:
    """What the precompute did and left out, in one line for the status bar and the panel."""
    r, info = sess.prt.report, sess.info
    world = "world: no rays (black)" if r["world_skipped"] else f"world: {info.world}"
    w = r.get("walks")
    walks = (f"; walks through the mesh: {w['walks_per_vertex']} x {w['walked_vertices']} vertices "
             f"({w['skipped_flat']} flat skipped)" if w else "")
    return (
        f"{len(sess.objects)} object(s) ({len(info.skipped_objects)} without the material skipped), "
        f"{r['lights_used']} light(s) used, {r['lights_skipped_black'] + len(info.skipped_lights)} dark "
        f"and {r['lights_unreached']} out of reach skipped, {world}; {r['samples']} samples, "
        f"{r['coefficients']} coefficients, support radius {r['support_radius']:.4g} units, "
        f"{r['rays']} rays{walks}, {r['seconds']:.2f} s"
    )


def state(material: bpy.types.Material) -> str:
    """'none', 'running', 'stale' or 'ready' for the panel."""
    if material.name in JOBS:
        return "running"
    s = SESSIONS.get(material.name)
    if s is None:
        return "none"
    if s.profile != material.translucent.profile_name():
        return "stale"
    if s.profile == "dipole" and abs(s.eta - material.translucent.eta) > 1e-9:
        return "stale"
    objects = [bpy.data.objects.get(n) for n in s.objects]
    if any(o is None for o in objects) or fingerprint(objects, bpy.context.scene) != s.fingerprint:
        return "stale"
    return "ready"


def principled_key(material: bpy.types.Material) -> str:
    """The Principled inputs the preview follows, as a string to compare."""
    from .properties import principled_inputs

    return repr(principled_inputs(material))


def edit(material: bpy.types.Material) -> None:
    """Refit and re-evaluate the material, and write every object's preview attribute."""
    import translucent

    from .properties import show_medium

    s = SESSIONS.get(material.name)
    if s is None or not material.translucent.enabled:
        return
    settings = material.translucent
    if settings.source == "PRINCIPLED":
        s.principled_key = principled_key(material)
    try:
        m = settings.material()
    except ValueError as e:
        s.edit_message = f"not shown: {e}"
        return
    if settings.source == "PRINCIPLED":
        show_medium(settings, m)
    if s.profile != settings.profile_name():
        return  # another profile needs a new precompute; the panel says so
    if s.profile == "dipole" and abs(s.eta - m.eta) > 1e-9:
        return  # the dipole's irradiance holds the IOR's Fresnel factor: precompute again
    if s.profile == "cycles" and not translucent.profile_ready(m) and not _prepare_tables(material, m):
        return  # the walk tables for a new g, Roughness or IOR are being built; old preview kept
    s.edit_message = ""
    prt = s.prt
    # Radiance leaving along each normal: a view-independent viewport colour.
    try:
        colors = prt.radiance(m)
    except ValueError as e:
        s.edit_message = f"not shown: {e}"
        return
    s.last_error = list(prt.last_eval["error_estimate"])
    s.last_seconds = prt.last_eval["seconds"]
    s.refresh_advised = bool(prt.last_eval["refresh_advised"])
    s.not_shown = []
    for name, values in writeback.split(colors, s.info).items():
        obj = bpy.data.objects.get(name)
        if obj is None:
            continue
        if len(obj.data.vertices) == len(values):
            writeback.write_colors(obj.data, values)
        elif name in s.remap and len(s.remap[name]) == len(obj.data.vertices):
            writeback.write_colors(obj.data, values[s.remap[name]])
        else:
            # The mesh changed since the precompute: the attribute cannot hold the values.
            s.not_shown.append(name)
    if s.refresh_advised:
        refresh(material)


def _prepare_tables(material: bpy.types.Material, m) -> bool:
    """Cycles' walk tables for `m` (new g, Roughness or IOR): built at once headless (returns
    True), else on a worker thread that never touches bpy, the edit running again when they are
    ready (returns False; the old preview stays up meanwhile)."""
    import translucent

    name = material.name
    if bpy.app.background:
        translucent.prepare_profile(m)
        return True
    s = SESSIONS[name]
    if name in PREPARING:
        return False
    s.edit_message = f"building Cycles' walk table (g {m.g:.2f}, Roughness {m.roughness:.2f}, IOR {m.eta:.2f})"
    errors = []

    def work():
        try:
            translucent.prepare_profile(m)
        except Exception as e:  # reported by the timer below, on the main thread
            errors.append(e)

    thread = threading.Thread(target=work, daemon=True)
    PREPARING[name] = thread
    thread.start()

    def poll():
        if thread.is_alive():
            return 0.2
        PREPARING.pop(name, None)
        mat = bpy.data.materials.get(name)
        if mat is not None:
            if errors:
                cur = SESSIONS.get(name)
                if cur is not None:
                    cur.edit_message = f"not shown: {errors[0]}"
            else:
                edit(mat)
            for window in bpy.context.window_manager.windows:
                for area in window.screen.areas:
                    area.tag_redraw()
        return None

    bpy.app.timers.register(poll, first_interval=0.2)
    return False


@bpy.app.handlers.persistent
def follow_principled(*_args) -> None:
    """depsgraph_update_post: a previewed material that follows its Principled BSDF is shown
    again when any input it reads has changed (cheap when none did)."""
    for name, s in list(SESSIONS.items()):
        mat = bpy.data.materials.get(name)
        if mat is None or not mat.translucent.enabled or mat.translucent.source != "PRINCIPLED":
            continue
        if principled_key(mat) != s.principled_key:
            edit(mat)


def refresh(material: bpy.types.Material) -> None:
    """The edit left the range the basis and samples were chosen for (the error estimate says
    so): precompute again for the current material in the background and swap the transport
    in when it is done; the preview keeps showing, flagged by the panel, meanwhile. Headless,
    it runs at once. Nothing happens while a job runs, or when the transport was already chosen
    for these very settings (no loop)."""
    s = SESSIONS.get(material.name)
    if s is None or material.name in JOBS or not material.translucent.auto_refresh:
        return
    if s.chosen_for == _params(material.translucent):
        return
    try:
        job, objects, info, fp = start(material)
    except ValueError as e:
        s.refresh_message = f"refresh failed: {e}"
        return
    JOBS[material.name] = job
    s.refresh_message = "refreshing the basis for the new material"
    name = material.name

    def complete() -> None:
        JOBS.pop(name, None)
        mat = bpy.data.materials.get(name)
        if mat is None:
            return
        if job.error is not None:
            cur = SESSIONS.get(name)
            if cur is not None:
                cur.refresh_message = f"refresh failed: {job.error}"
            return
        finish(mat, job, objects, info, fp)

    if bpy.app.background:
        job.run_here()
        complete()
        return

    def poll():
        if not job.done:
            return 0.2
        complete()
        for window in bpy.context.window_manager.windows:
            for area in window.screen.areas:
                area.tag_redraw()
        return None

    job.start()
    bpy.app.timers.register(poll, first_interval=0.2)
