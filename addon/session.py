"""The transport of each previewed material, held in memory (never saved: a reloaded file asks
for a new precompute), the edit path (refit + dot product + write-back), and the scene
following: a depsgraph handler notices a previewed object deforming or a light or the world
changing, and a debounced timer checks and refreshes the transport in the background.

How a transport is built is the method's: PRT (Xu 2007) today; the hierarchy (Mertens 2003)
plugs in through `resolve_method` and `HierarchyJob` once `translucent.Hierarchy` exists."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field

import bpy
import numpy as np

from . import export, viewport, writeback


@dataclass
class Session:
    prt: object  # translucent.Prt, or the hierarchy's transport (`HierarchyTransport`)
    info: export.ExportInfo
    objects: list[str]
    # export.lighting_keys at the precompute: what each light and the world were.
    lighting: dict
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
    # "prt" or "hierarchy": what built the transport, and why it is not the method asked for.
    method: str = "prt"
    method_message: str = ""
    # Objects whose evaluated geometry differs from the transport's: name -> "deformed",
    # "topology" (vertex count) or "removed". Kept by the follow check, read by the panel.
    deformed: dict = field(default_factory=dict)
    # What differs from the transport ("" when nothing): the panel's "stale" and its reason.
    changed: str = ""
    # Mesh objects that took or lost the material since ("" when none), in words.
    members_changed: str = ""
    # What following the scene is doing ("refreshing: light Key changed", ...).
    follow_message: str = ""
    # The viewport's eye point the preview is drawn toward (world space), when the transport
    # holds single scattering (view dependent, Xu 2007 eq. 5); None: along each normal.
    eye: tuple | None = None


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


class HierarchyTransport:
    """A `translucent.Hierarchy` seen through the calls the edit path makes on a `Prt`
    (`radiance(m)`, `last_eval`, `report`, `profile`). Written against the hierarchy's announced
    API (`Hierarchy(scene, material, profile=, eps=, mode=)`, `.radiance(material, eye)`,
    `.update(positions=, lights=)`); untested until translucent has it."""

    def __init__(self, hierarchy, profile: str):
        self.hierarchy = hierarchy
        self.profile = profile
        self.backend_message = "hierarchy (Mertens 2003)"
        self.last_eval = {"error_estimate": [0.0, 0.0, 0.0], "seconds": 0.0, "refresh_advised": False}

    @property
    def report(self) -> dict:
        r = dict(getattr(self.hierarchy, "report", None) or {})
        for key, value in (("world_skipped", False), ("walks", None), ("lights_used", 0), ("lights_skipped_black", 0),
                           ("lights_unreached", 0), ("samples", 0), ("coefficients", 0), ("support_radius", 0.0),
                           ("rays", 0), ("seconds", 0.0), ("vertices", 0)):
            r.setdefault(key, value)
        return r

    def radiance(self, m):
        # Along the normals, as the PRT preview shows it: no eye point.
        colors = self.hierarchy.radiance(m, None)
        last = getattr(self.hierarchy, "last_eval", None)
        if last:
            self.last_eval.update(last)
        return colors


class HierarchyJob(Job):
    """The hierarchy built (or updated, same topology) on a worker thread; the same polling."""

    def __init__(self, scene, material, previous: HierarchyTransport | None = None, positions=None, **kwargs):
        super().__init__(scene, [material], **kwargs)
        self._material, self._previous, self._positions = material, previous, positions

    def _run(self, scene, materials, kwargs):
        import translucent

        try:
            profile = kwargs.get("profile", "cycles")
            if self._previous is not None:
                # Same topology: the hierarchy's own update (links promoted or demoted).
                self._previous.hierarchy.update(positions=self._positions, lights=scene)
                self.result = self._previous
            else:
                # The world shadowed by the mesh, as Cycles renders it.
                h = translucent.Hierarchy(scene, self._material, profile=profile, eps=HIERARCHY_EPS,
                                          mode="on_the_fly", world_shadows=True)
                self.result = HierarchyTransport(h, profile)
        except BaseException as e:  # reported by the follow refresh, which falls back to PRT
            self.error = e


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


# ------------------------------------------------------------------------------- methods

HIERARCHY_EPS = (0.005, 0.5)  # receiver and emitter thresholds (eps1, eps2): translucent.Hierarchy's defaults


def hierarchy_available() -> bool:
    import translucent

    return hasattr(translucent, "Hierarchy")


HIERARCHY_MISSING = "Hierarchy: not in this build of translucent (no translucent.Hierarchy), PRT used"


def resolve_method(setting: str, change: str, current: str = "prt") -> tuple[str, str]:
    """The method ("prt" or "hierarchy") that builds the transport for a `change` ("precompute",
    "deformation", "light") under the panel's `setting` ("PRT", "HIERARCHY", "AUTO"), and why it
    is not the one asked for ("" when it is). Auto: the hierarchy for a deformation, and for a
    light when the hierarchy already holds the transport (its render mode); PRT otherwise (the
    button, material editing: PRT's edits are dot products)."""
    if setting == "PRT":
        return "prt", ""
    wants = setting == "HIERARCHY" or change == "deformation" or (change == "light" and current == "hierarchy")
    if not wants:
        return "prt", ""
    if not hierarchy_available():
        return "prt", HIERARCHY_MISSING
    return "hierarchy", ""


def start(material: bpy.types.Material, bl_scene=None, method: str = "prt",
          previous: Session | None = None) -> tuple[Job, list[str], export.ExportInfo, dict]:
    """Exports what the material needs and creates (but does not start) the job that builds its
    transport: PRT's precompute, or the hierarchy (updated in place from `previous` when the
    topology is the same). Returns the job, the objects, the export info and the lighting keys."""
    bl_scene = bl_scene or bpy.context.scene
    objects = objects_with(material, bl_scene)
    if not objects:
        raise ValueError(f"no mesh object uses material {material.name!r}")
    scene, info = export.export_scene(objects, bl_scene=bl_scene)
    info.skipped_objects = [o.name for o in bl_scene.objects if o.type == "MESH" and o not in objects]
    s = material.translucent
    if method == "hierarchy":
        same = (previous is not None and previous.method == "hierarchy"
                and [(r.name, r.count) for r in previous.info.objects] == [(r.name, r.count) for r in info.objects])
        positions = None
        if same:
            depsgraph = bpy.context.evaluated_depsgraph_get()
            positions = np.concatenate([export.evaluated_mesh_arrays(o, depsgraph)[0] for o in objects])
        job = HierarchyJob(scene, s.material(), previous=previous.prt if same else None, positions=positions,
                           profile=s.profile_name())
    else:
        job = Job(scene, [s.material()], coefficients=s.coefficients, degree=int(s.degree), backend=s.backend,
                  profile=s.profile_name())
    job.method = method
    job.chosen_for = _params(s)
    job.profile = s.profile_name()
    return job, [o.name for o in objects], info, export.lighting_keys(bl_scene)


def finish(material: bpy.types.Material, job: Job, objects, info, lighting, method_message: str = "") -> Session:
    """The finished job's transport becomes the material's session (the old one, still shown
    until now, is dropped) and the preview is written from it."""
    session = Session(job.result, info, objects, lighting, material.translucent.eta, profile=job.profile)
    session.chosen_for = job.chosen_for
    session.method = getattr(job, "method", "prt")
    session.method_message = method_message
    session.remap = nearest_original_vertices(objects, info)
    SESSIONS[material.name] = session
    edit(material)
    viewport.show([o for o in (bpy.data.objects.get(n) for n in objects) if o is not None])
    return session


def summary(sess: Session) -> str:
    """What the precompute did and left out, in one line for the status bar and the panel."""
    r, info = sess.prt.report, sess.info
    if sess.method == "hierarchy":
        # Its report's keys are the hierarchy's own: shown as it gives them, not as PRT's.
        own = ", ".join(f"{k} {v}" for k, v in dict(getattr(sess.prt.hierarchy, "report", None) or {}).items())
        return (f"{len(sess.objects)} object(s) ({len(info.skipped_objects)} without the material skipped), "
                f"{len(info.lights)} light(s), {len(info.skipped_lights)} dark skipped, world: {info.world}; "
                f"hierarchy (Mertens 2003){': ' + own if own else ''}")
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
    """'none', 'running', 'stale' or 'ready' for the panel; cheap (it runs on every redraw)."""
    if material.name in JOBS:
        return "running"
    s = SESSIONS.get(material.name)
    if s is None:
        return "none"
    if s.profile != material.translucent.profile_name():
        return "stale"
    if s.profile == "dipole" and abs(s.eta - material.translucent.eta) > 1e-9:
        return "stale"
    # What the follow handler and check found (no mesh is evaluated here: the panel calls this).
    if s.changed or any(bpy.data.objects.get(n) is None for n in s.objects):
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
    if s.method == "hierarchy" and material.name in JOBS:
        return  # the hierarchy is being updated in place on a worker thread: shown when done
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
    # Radiance leaving along each normal (a view-independent viewport colour), or toward the
    # viewport's eye where single scattering makes it depend on the view.
    try:
        colors = prt.radiance(m, s.eye) if s.eye is not None and view_dependent(s) else prt.radiance(m)
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
        job, objects, info, lighting = start(material)
    except ValueError as e:
        s.refresh_message = f"refresh failed: {e}"
        return
    s.refresh_message = "refreshing the basis for the new material"

    def failed(error):
        cur = SESSIONS.get(material.name)
        if cur is not None:
            cur.refresh_message = f"refresh failed: {error}"

    _in_background(material.name, job, objects, info, lighting, failed)


def _in_background(name: str, job: Job, objects, info, lighting, failed, method_message: str = "") -> None:
    """Runs `job` off the UI thread (headless: here, at once) and swaps its transport in when it
    is done; until then the old preview stays up. `failed(error)` reports an error."""
    JOBS[name] = job
    job.background = True  # the panel: no Esc to cancel it (no modal operator runs it)

    def complete() -> None:
        JOBS.pop(name, None)
        mat = bpy.data.materials.get(name)
        if mat is None:
            return
        if job.error is not None:
            failed(job.error)
            return
        finish(mat, job, objects, info, lighting, method_message)

    if _headless():
        job.run_here()
        complete()
        return

    def poll():
        if not job.done:
            return 0.2
        complete()
        _redraw()
        return None

    job.start()
    bpy.app.timers.register(poll, first_interval=0.2)


def _headless() -> bool:
    """No UI to keep responsive (tests may pretend there is one)."""
    return bpy.app.background


def _redraw() -> None:
    wm = getattr(bpy.context, "window_manager", None)
    for window in wm.windows if wm is not None else ():
        for area in window.screen.areas:
            area.tag_redraw()


# ----------------------------------------------------------------------- following the scene
#
# The depsgraph handler only takes notes (which previewed objects' geometry or transform was
# tagged; a changed light or world is compared at once, it is cheap); a timer runs once the
# scene has been still for DEBOUNCE_S, evaluates the tagged objects to tell a deformation from
# the add-on's own colour writes (those tag the mesh too), and refreshes in the background.

DEBOUNCE_S = 0.3
# material name -> (clock at the last change noticed, objects whose geometry may have changed)
PENDING: dict[str, tuple[float, set]] = {}
_clock = time.monotonic  # tests may replace it


def _lighting_difference(old: dict, new: dict) -> str:
    """What differs between two `export.lighting_keys`, in words ("" when nothing)."""
    parts = []
    for key in sorted(set(old) | set(new)):
        if key not in new:
            parts.append(f"{key} removed")
        elif key not in old:
            parts.append(f"{key} added")
        elif old[key] != new[key]:
            parts.append(f"{key} changed")
    return ", ".join(parts)


def _describe(s: Session, lighting: str) -> str:
    parts = [f"{name} {'changed topology' if what == 'topology' else what}" for name, what in sorted(s.deformed.items())]
    if s.members_changed:
        parts.append(s.members_changed)
    if lighting:
        parts.append(lighting)
    return ", ".join(parts)


def _note(name: str, objects=()) -> None:
    _, suspects = PENDING.get(name, (0.0, set()))
    PENDING[name] = (_clock(), suspects | set(objects))
    if not bpy.app.timers.is_registered(follow_tick):
        bpy.app.timers.register(follow_tick, first_interval=DEBOUNCE_S)


def _is_lighting(id_) -> bool:
    return (isinstance(id_, (bpy.types.Light, bpy.types.World, bpy.types.Scene))
            or (isinstance(id_, bpy.types.Object) and id_.type == "LIGHT")
            or (isinstance(id_, bpy.types.NodeTree) and id_.bl_idname == "ShaderNodeTree"))


@bpy.app.handlers.persistent
def follow_scene(scene, depsgraph) -> None:
    """depsgraph_update_post: notes which previewed objects deformed or moved (geometry or
    transform tagged: armature, shape keys, modifiers, edit mode) and whether a light or the
    world changed, and schedules the debounced check. Evaluates no mesh."""
    if not SESSIONS:
        return
    tagged, lighting, linked = set(), False, False
    for u in depsgraph.updates:
        id_ = u.id.original
        if isinstance(id_, bpy.types.Object) and id_.type == "MESH" and (u.is_updated_geometry or u.is_updated_transform):
            tagged.add(id_.name)
        elif _is_lighting(id_):
            lighting = True
        # Objects linked, unlinked or given a material: which objects carry it may differ.
        linked = linked or isinstance(id_, (bpy.types.Scene, bpy.types.Collection))
    _follow(scene, tagged, lighting, linked)


@bpy.app.handlers.persistent
def follow_frame(scene, depsgraph=None) -> None:
    """frame_change_post (timeline scrub, playback): anything may be animated, so every
    previewed object is checked once the timeline is still."""
    if SESSIONS:
        _follow(scene, None, True)


def _follow(scene, tagged: set | None, lighting: bool, linked: bool = True) -> None:
    keys = export.lighting_keys(scene) if lighting else None
    for name, s in list(SESSIONS.items()):
        if bpy.data.materials.get(name) is None:
            continue
        moved = set(s.objects) if tagged is None else tagged & set(s.objects)
        others = linked or (tagged is not None and bool(tagged - moved))
        lit = ""
        if keys is not None:
            lit = _lighting_difference(s.lighting, keys)
            s.changed = _describe(s, lit)  # the panel says "stale" at once; geometry after the check
        if moved or lit or others:
            _note(name, moved)


def follow_again(material: bpy.types.Material) -> None:
    """Following was switched on (or the preview on again): check every previewed object and
    the lights once the timer runs, and refresh what changed meanwhile."""
    s = SESSIONS.get(material.name)
    if s is not None:
        _note(material.name, s.objects)


def follow_tick() -> float | None:
    """The timer: once a material's scene has been still for DEBOUNCE_S, `follow_now` for it.
    Returns when to run again (None: nothing pending)."""
    now = _clock()
    due = [n for n, (t, _) in PENDING.items() if now - t >= DEBOUNCE_S]
    follow_now(due)
    if not PENDING:
        return None
    return max(0.05, min(DEBOUNCE_S - (now - t) for t, _ in PENDING.values()))


def follow_now(names=None) -> None:
    """Checks what the handler noted (all pending materials, or `names`) and refreshes the
    transport of those that changed, in the background: PRT again, or the hierarchy (see
    `resolve_method`). A material whose job still runs stays pending: checked when it is done."""
    for name in list(PENDING if names is None else names):
        if name not in PENDING or name in JOBS or name in PREPARING:
            continue
        _, suspects = PENDING.pop(name)
        s, mat = SESSIONS.get(name), bpy.data.materials.get(name)
        if s is None or mat is None:
            continue
        objects = [bpy.data.objects.get(n) for n in s.objects]
        if any(o is not None and o.mode == "EDIT" for o in objects):
            # The preview attribute written now would be lost when Edit Mode writes its mesh
            # back: leaving Edit Mode tags the geometry again, and the preview follows then.
            s.follow_message = "in Edit Mode: the preview follows when you leave it"
            continue
        _check(s, mat, suspects, bpy.context.scene)
        settings = mat.translucent
        if s.changed and settings.enabled and settings.follow_scene:
            _follow_refresh(mat, s)


def _check(s: Session, mat: bpy.types.Material, suspects: set, bl_scene) -> None:
    """Compares the tagged objects' evaluated geometry, which objects carry the material, and
    the lights and world with what the transport was built from, and keeps the result on the
    session (`deformed`, `members_changed`, `changed`)."""
    members = {o.name for o in objects_with(mat, bl_scene)}
    gained, lost = sorted(members - set(s.objects)), sorted(set(s.objects) - members)
    s.members_changed = ", ".join([f"{n} took the material" for n in gained] + [f"{n} lost it" for n in lost])
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for r in s.info.objects:
        if r.name not in suspects:
            continue
        obj = bpy.data.objects.get(r.name)
        if obj is None:
            s.deformed[r.name] = "removed"
            continue
        key = export.object_geometry_key(obj, depsgraph)
        if key == r.geometry_key:
            s.deformed.pop(r.name, None)  # the add-on's own colour write, or moved back
        elif key.split(":")[0] != str(r.count):
            s.deformed[r.name] = "topology"
        else:
            s.deformed[r.name] = "deformed"
    s.changed = _describe(s, _lighting_difference(s.lighting, export.lighting_keys(bl_scene)))


def _follow_refresh(mat: bpy.types.Material, s: Session) -> None:
    """Builds the transport again for the scene as it is now, in the background; the old
    preview stays up until the new one is written. A topology change always starts from
    scratch; the hierarchy updates itself in place otherwise."""
    change = "deformation" if s.deformed else "light"
    method, message = resolve_method(mat.translucent.method, change, s.method)
    topology = any(v != "deformed" for v in s.deformed.values()) or bool(s.members_changed)
    name = mat.name
    try:
        job, objects, info, lighting = start(mat, method=method, previous=None if topology else s)
    except ValueError as e:
        s.follow_message = f"following the scene failed: {e}"
        return
    s.follow_message = f"refreshing ({'PRT' if method == 'prt' else 'hierarchy'}): {s.changed}"

    def failed(error):
        cur = SESSIONS.get(name)
        if cur is not None:
            cur.follow_message = f"following the scene failed: {error}"

    def hierarchy_failed(error):
        # The hierarchy is new: when it fails, PRT keeps the preview following, saying why.
        material = bpy.data.materials.get(name)
        if material is None:
            return
        why = f"hierarchy failed ({error}), PRT used"
        try:
            job2, objects2, info2, lighting2 = start(material, method="prt")
        except ValueError as e:
            failed(e)
            return
        _in_background(name, job2, objects2, info2, lighting2, failed, why)

    _in_background(name, job, objects, info, lighting, hierarchy_failed if method == "hierarchy" else failed, message)


# How far the eye must move, relative to its distance from the origin plus 1 unit, before the
# view-dependent preview is drawn again; and how often the viewport's view is looked at [s].
EYE_TOLERANCE = 1e-3
VIEW_POLL_S = 0.2


def view_dependent(s: Session) -> bool:
    """Whether the session's transport holds single scattering (the dipole's L^(1)): only then
    does the preview depend on where the viewer is."""
    return s.method == "prt" and bool(dict(getattr(s.prt, "report", {}) or {}).get("single_scattering"))


def viewport_eye() -> tuple | None:
    """The eye point of the first 3D viewport (world space), or None without one (headless)."""
    wm = getattr(bpy.context, "window_manager", None)
    for window in getattr(wm, "windows", []):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                r3d = area.spaces.active.region_3d
                if r3d is not None:
                    return tuple(r3d.view_matrix.inverted().translation)
    return None


def set_eye(material: bpy.types.Material, eye) -> bool:
    """Draws the material's preview toward `eye` (world space; None: along the normals) when
    it depends on the view; returns whether it was drawn again."""
    s = SESSIONS.get(material.name)
    if s is None or not view_dependent(s):
        return False
    if eye is not None:
        eye = tuple(float(x) for x in eye)
        if s.eye is not None:
            moved = sum((a - b) ** 2 for a, b in zip(eye, s.eye)) ** 0.5
            if moved <= EYE_TOLERANCE * (1.0 + sum(a * a for a in eye) ** 0.5):
                return False
    elif s.eye is None:
        return False
    s.eye = eye
    edit(material)
    return True


def follow_view_tick() -> float:
    """Timer: the viewport's view moved, so the view-dependent previews are drawn toward it
    (sliders stay live: an edit draws toward the last eye)."""
    eye = viewport_eye()
    if eye is not None:
        for name in list(SESSIONS):
            mat = bpy.data.materials.get(name)
            if mat is not None and name not in JOBS:
                set_eye(mat, eye)
    return VIEW_POLL_S
