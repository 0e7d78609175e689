"""Background jobs: a material's transport built on a worker thread that never touches bpy, by
the method `resolve_method` picks (PRT, Xu 2007, or the hierarchy, Mertens 2003)."""

from __future__ import annotations

import threading
import time

import bpy

from . import export, textures
from .session import JOBS, SESSIONS, objects_with, params


# The share of the progress bar a first preview takes (it costs a few per cent of the whole).
FIRST_PREVIEW_SHARE = 0.03


class Job:
    """A precompute on a worker thread that never touches bpy; the operator polls it.

    With `first_preview`, a first preview (`Prt(first_preview=True)`: no walks, fewer samples,
    a cheap own light; 0.8 s on the 10 cm bunny of a 15-20 s precompute) is built first and kept
    as `first` (with `first_seconds` since the start) for the operator to show while the full
    precompute runs; it is only worth it where the walks run (Cycles' profile)."""

    def __init__(self, scene, materials, first_preview: bool = False, **kwargs):
        self.progress = 0.0
        self.cancel = False
        self.result = None
        self.first = None
        self.first_seconds: float | None = None
        self.first_preview = first_preview
        self.error: BaseException | None = None
        self.scene = scene  # the translucent.Scene the result is lit with (`LayersPrep`)
        self._span = (0.0, 1.0)
        self._thread = threading.Thread(target=self._run, args=(scene, materials, kwargs), daemon=True)

    def _tick(self, f: float) -> bool:
        lo, hi = self._span
        self.progress = lo + (hi - lo) * f
        return not self.cancel

    def _run(self, scene, materials, kwargs):
        import translucent

        try:
            if self.first_preview:
                t0 = time.perf_counter()
                self._span = (0.0, FIRST_PREVIEW_SHARE)
                first_kwargs = {k: v for k, v in kwargs.items() if k in ("coefficients", "degree", "backend", "profile")}
                self.first = translucent.Prt(scene, materials, progress=self._tick, first_preview=True, **first_kwargs)
                self.first_seconds = time.perf_counter() - t0
                self._span = (FIRST_PREVIEW_SHARE, 1.0)
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


HIERARCHY_EPS = (0.005, 0.5)  # receiver and emitter thresholds (eps1, eps2): translucent.Hierarchy's defaults
# Receivers the hierarchy checks against its ground truth for its error estimate (its
# default); 0 computes none, and the panel then says so.
HIERARCHY_ESTIMATE_RECEIVERS = 32


class HierarchyJob(Job):
    """The hierarchy built (or updated, same topology) on a worker thread; the same polling. Its
    result is the `translucent.Hierarchy` itself: it answers the edit path's calls as a `Prt`
    does (`radiance`, `last_eval`, `report`, `profile`), each with its own keys. With Cycles'
    profile it takes the walks' term and the object's own light (`walks=True`, as PRT has
    them); after a pose they are carried at once ("posed (refining)", `retrace` set) and then
    walked on the pose by a `RetraceJob` ("refined")."""

    def __init__(self, scene, material, previous=None, positions=None, key=None, **kwargs):
        super().__init__(scene, [material], **kwargs)
        self._material, self._previous, self._positions = material, previous, positions
        self.stage_message = ""
        self.retrace = False
        # What it is evaluated for at its end (`session.params` and the texture's key), with the
        # radiance, evaluation and report then: the edit that shows it evaluates nothing again.
        self.key = key
        self.colors = self.last_eval = self.report = None

    def _run(self, scene, materials, kwargs):
        import translucent

        try:
            if self._previous is not None:
                # Same topology: the hierarchy's own update (links promoted or demoted).
                h = self._previous
                if self._positions is not None:
                    # The exported mesh's own normals (Blender's), as a fresh build takes them.
                    h.update(positions=scene.positions, normals=scene.normals, lights=scene)
                else:
                    h.update(lights=scene)
                # With walks, a pose carries them at once; `RetraceJob` then walks the pose.
                self.retrace = h.report.get("terms") is not None and self._positions is not None
                if self.retrace:
                    t0 = time.perf_counter()
                    evaluate(self, h, self._material)
                    self.stage_message = (f"posed (refining): the walks carried to the pose in "
                                          f"{time.perf_counter() - t0:.2f} s, tracing them on it")
                self.result = h
            else:
                # The world shadowed by the mesh, as Cycles renders it; Cycles' walks through
                # the mesh and its own light with Cycles' profile.
                self._span = (0.0, 0.5)
                self.result = translucent.Hierarchy(scene, self._material, profile=kwargs["profile"],
                                                    eps=HIERARCHY_EPS, mode="on_the_fly", world_shadows=True,
                                                    estimate_receivers=HIERARCHY_ESTIMATE_RECEIVERS,
                                                    walks=kwargs["profile"] == "cycles", progress=self._tick)
                self._span = (0.5, 1.0)
            if self.colors is None:
                # The preview evaluated here, off the UI thread (a Base Color per vertex: its
                # media summed, those beyond the walked lengths walked now, not at the first edit).
                evaluate(self, self.result, self._material)
        except BaseException as e:  # reported by the follow refresh, which falls back to PRT
            self.error = e


def per_vertex(job: Job) -> dict:
    """The job's Base Color and Subsurface Weight per vertex, where read, as the hierarchy's and
    the splatting's keyword arguments (media blended around each vertex's colour, the lobes
    split by its weight)."""
    read = (("base_color", getattr(job, "base_color", None)),
            ("subsurface_weight", getattr(job, "subsurface_weight", None)))
    return {k: v for k, v in read if v is not None}


def evaluate(job: Job, hierarchy, material) -> None:
    """`hierarchy`'s radiance along the normals for `material` (with the job's Base Color and
    Subsurface Weight per vertex where it has them), kept on the job as `colors` with its
    `last_eval` and `report`
    for the edit that shows it; on the worker thread, stopping when the job is cancelled."""
    job.colors = hierarchy.radiance(material, progress=job._tick, **per_vertex(job))
    job.last_eval, job.report = dict(hierarchy.last_eval), dict(hierarchy.report)


class EditJob(Job):
    """An edit of a material the hierarchy previews, evaluated on a worker thread that never
    touches bpy: the hierarchy sums its links again for every material (2.1 s on the 10 cm
    bunny, 4.5 s with a Base Color per vertex, 2-core AMD EPYC), which would freeze the UI. The
    result is the same `translucent.Hierarchy`; `colors`, `last_eval` and `report` what it gave
    for `key` (`session.params` and the texture's key). `supersedable`: the next edit cancels it
    (its progress then returns False) and runs as soon as it has stopped."""

    supersedable = True
    label = "Evaluating the edit in the background"

    def __init__(self, hierarchy, material, key):
        super().__init__(None, [material])
        self._hierarchy, self._material = hierarchy, material
        self.key = key
        self.colors = self.last_eval = self.report = None

    def _run(self, scene, materials, kwargs):
        try:
            evaluate(self, self._hierarchy, self._material)
            self.result = self._hierarchy
        except BaseException as e:  # a cancel (the next edit) or an error: the edit path reads it
            self.error = e


class RetraceJob(Job):
    """The hierarchy's walks traced on the pose they were carried to (`retrace_walks`), on a
    worker thread; its result is the same `translucent.Hierarchy`."""

    def __init__(self, hierarchy, material, **kwargs):
        super().__init__(None, [material], **kwargs)
        self._hierarchy, self._material = hierarchy, material
        self.stage_message = ""
        self.key = self.colors = self.last_eval = self.report = None  # as `evaluate` leaves them

    def _run(self, scene, materials, kwargs):
        try:
            t0 = time.perf_counter()
            self._hierarchy.retrace_walks()
            evaluate(self, self._hierarchy, self._material)
            self.stage_message = f"refined: walks traced on the pose in {time.perf_counter() - t0:.2f} s"
            self.result = self._hierarchy
        except BaseException as e:  # reported by the follow refresh
            self.error = e


class RelightJob(Job):
    """PRT under new lights, same mesh: `Prt.update(lights=scene)` on a worker thread (no
    walk traced; the old transport answers edits until the new one is in). Its result is the
    same `translucent.Prt`. Should the update refuse (the exported mesh differs after all), a
    fresh precompute runs instead."""

    def __init__(self, scene, materials, previous, **kwargs):
        super().__init__(scene, materials, **kwargs)
        self._previous = previous
        self.stage_message = ""

    def _run(self, scene, materials, kwargs):
        import translucent

        try:
            try:
                r = self._previous.update(lights=scene, progress=self._tick)
                # One light's power or colour alone: its own layer added (relit once, then kept).
                layer = ""
                if r.get("from_layer"):
                    layer = (f", the light's layer relit in {r['seconds_layer']:.2f} s" if r["seconds_layer"] > 0
                             else ", the light's layer rescaled")
                self.stage_message = (f"relit: {r['seconds']:.2f} s, {r['walks_traced']} walks traced, "
                                      f"{r['rays'] + r['own_light_rays']:,} rays{layer}")
                self.result = self._previous
            except ValueError as e:
                self.result = translucent.Prt(scene, materials, progress=self._tick, **kwargs)
                self.stage_message = f"precomputed again ({e})"
        except BaseException as e:  # reported to the user by the follow refresh
            self.error = e


# The share of the progress bar a pose's carried preview takes, before the walks on the pose.
POSE_SHARE = 0.1


class PoseJob(Job):
    """PRT after a deformation of the same mesh: first the `previous` Prt carried to the pose
    (`Prt.update(lights=scene)` with the posed scene: samples, irradiance and transport on the
    posed mesh, the walks and the own light read on the same triangles, none traced), kept as
    `first` for the preview at once ("posed (refining)"); then a precompute on the posed mesh,
    the walks traced on it ("refined"). Should the update refuse (another topology after all),
    only the precompute runs."""

    def __init__(self, scene, materials, previous, **kwargs):
        super().__init__(scene, materials, **kwargs)
        self._previous = previous
        self.stage_message = ""
        self.first_message = ""

    def _run(self, scene, materials, kwargs):
        import translucent

        try:
            t0 = time.perf_counter()
            self._span = (0.0, POSE_SHARE)
            try:
                r = self._previous.update(lights=scene, progress=self._tick)
                self.first_seconds = time.perf_counter() - t0
                self.first_message = (f"posed (refining): the walks carried to the pose in {r['seconds']:.2f} s, "
                                      f"tracing them on it")
                self.first = self._previous
                prefix = f"refined: walks traced on the pose after {self.first_seconds:.2f} s carried"
            except ValueError as e:
                prefix = f"precomputed again ({e})"
            self._span = (POSE_SHARE, 1.0)
            self.result = translucent.Prt(scene, materials, progress=self._tick, **kwargs)
            self.stage_message = prefix
        except BaseException as e:  # reported to the user by the follow refresh
            self.error = e


# Vertices the splatting checks against its ground truth for its error estimate per evaluation
# (the image's too, `splat_view.ESTIMATE_RECEIVERS`): about 0.1-0.2 s a vertex on a 10 cm bunny.
SPLAT_ESTIMATE_RECEIVERS = 8


def splat_settings(bl_scene) -> tuple:
    """(eps, max_grid, backend) of the scene's splatting settings (`translucent_splat`): the
    per-vertex Method = Splatting and the camera image share them."""
    v = bl_scene.translucent_splat
    return (float(v.eps), int(v.max_grid), v.backend.lower())


class SplatJob(Job):
    """Method = Splatting (Shah 2009), per vertex: nothing is precomputed, so every evaluation
    splats the scene again, on a worker thread that never touches bpy. Builds a
    `translucent.Splat` (or takes the `previous` one: `update(lights=scene)` for a light change,
    `update(positions=..., normals=..., lights=scene)` for a pose of the same mesh) and
    evaluates the radiance along the normals for `material`. The result is the Splat; `colors`
    the (N, 3) radiance, `key` what it was evaluated for, `last_eval` its evaluation. A pose
    with the walks on is shown twice, as the hierarchy's is: first with the walks carried to
    it (`first`, `first_colors`: "posed (refining)"), then walked on it ("refined")."""

    def __init__(self, scene, material, key, previous=None, change: str = "", profile: str = "cycles",
                 settings: tuple = (0.01, 1024, "auto")):
        super().__init__(scene, [material])
        self._material, self._previous, self._change = material, previous, change
        self._profile, self._settings = profile, settings
        self.key = key
        self.colors = self.first_colors = None
        self.last_eval = self.first_eval = self.report = self.first_report = None
        self.stage_message = self.first_message = ""

    def _run(self, scene, materials, kwargs):
        import translucent

        try:
            t0 = time.perf_counter()
            splat = self._previous
            if splat is None:
                eps, max_grid, backend = self._settings
                # reuse: a dragged light or a turning object does not flicker (Shah's two grids).
                splat = translucent.Splat(scene, profile=self._profile, eps=eps, max_grid=max_grid,
                                          walks=self._profile == "cycles", backend=backend, reuse=True,
                                          estimate_receivers=SPLAT_ESTIMATE_RECEIVERS)
            elif self._change == "deformation":
                splat.update(positions=scene.positions, normals=scene.normals, lights=scene)
            elif self._change == "light":
                splat.update(lights=scene)
            posed = self._change == "deformation" and splat.walks
            self._span = (0.0, POSE_SHARE) if posed else (0.0, 1.0)
            textured = per_vertex(self)  # media blended per vertex, lobes split by the weight
            colors = splat.radiance(self._material, progress=self._tick, **textured)
            what = {"light": "lights changed: ", "deformation": "posed: "}.get(self._change, "")
            if posed:
                self.first_seconds = time.perf_counter() - t0
                self.first_colors, self.first_eval, self.first_report = colors, dict(splat.last_eval), dict(splat.report)
                self.first_message = (f"posed (refining): splatted with the walks carried to the pose in "
                                      f"{self.first_seconds:.2f} s, tracing them on it")
                self.first = splat
                self._span = (POSE_SHARE, 1.0)
                splat.retrace_walks()
                colors = splat.radiance(self._material, progress=self._tick, **textured)
                what = f"refined: walks traced on the pose after {self.first_seconds:.2f} s carried; "
            self.colors, self.last_eval, self.report = colors, dict(splat.last_eval), dict(splat.report)
            self.stage_message = (f"splatted ({what}nothing precomputed): {time.perf_counter() - t0:.2f} s, "
                                  f"{splat.report['splats']:,} splats")
            self.result = splat
        except BaseException as e:  # reported to the user by the operator or the follow refresh
            self.error = e


METHOD_NAMES = {"prt": "PRT", "hierarchy": "hierarchy", "splat": "splatting"}


def hierarchy_available() -> bool:
    import translucent

    return hasattr(translucent, "Hierarchy")


HIERARCHY_MISSING = "Hierarchy: not in this build of translucent (no translucent.Hierarchy), PRT used"


def resolve_method(setting: str, change: str, current: str = "prt") -> tuple[str, str]:
    """The method ("prt", "hierarchy" or "splat") that builds the transport for a `change`
    ("precompute", "deformation", "light") under the panel's `setting` ("PRT", "HIERARCHY",
    "SPLAT", "AUTO"), and why it is not the one asked for ("" when it is). Auto: the method that
    holds the transport for a deformation or a light (PRT carries its walks and own light to a
    pose, `PoseJob`, and relights without a walk; the hierarchy updates itself in place); PRT
    otherwise (the button, material editing: PRT's edits are dot products). Splatting only
    when asked for: each of its edits splats again (seconds, in the background)."""
    if setting == "PRT":
        return "prt", ""
    if setting == "SPLAT":
        return "splat", ""
    wants = setting == "HIERARCHY" or (change in ("deformation", "light") and current == "hierarchy")
    if not wants:
        return "prt", ""
    if not hierarchy_available():
        return "prt", HIERARCHY_MISSING
    return "hierarchy", ""


class LayersPrep:
    """Each light's own layer of a PRT transport made on a worker thread once it is shown
    (`Prt.prepare_layers`), so that the first drag of one light's power or colour among
    several adds its layer (no ray: 0.12-0.14 s from the change to the preview on the 10 cm
    bunny) instead of relighting the transport under that light alone first (1.75 s), as every
    later drag already did. With a UI only: a
    script's `update` relights a layer at its first change. `stop()` ends it at its next
    progress call; `start` calls it before any other job on the material begins. `message`:
    what the panel says of it ("" where no layer was needed: a lone light)."""

    def __init__(self, prt, scene):
        self.message = "preparing the lights' layers"
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(prt, scene), daemon=True)
        self._thread.start()

    def _run(self, prt, scene):
        import translucent

        try:
            r = prt.prepare_layers(scene, progress=lambda f: not self._stop.is_set())
        except translucent.Cancelled:
            self.message = ""
            return
        except Exception as e:  # noqa: BLE001 - the panel says it; the preview is not affected
            self.message = f"the lights' layers were not prepared: {e}"
            return
        ready = r["built"] + r["kept"]
        self.message = (f"lights' layers ready: {ready} ({r['seconds']:.1f} s, {r['layer_bytes'] / 1e6:.0f} MB): "
                        f"a drag of one light's power or colour adds its layer, no ray" if ready else "")

    def stop(self) -> None:
        """Asks it to stop and waits until it has (its next progress call: moments)."""
        self._stop.set()
        self._thread.join(timeout=60)

    @property
    def done(self) -> bool:
        return not self._thread.is_alive()


def prepare_layers(session, scene) -> None:
    """With a UI, the lights' layers of the session's PRT transport made in the background
    (`LayersPrep`); headless, or for the other methods, nothing."""
    if headless() or session.method != "prt" or scene is None or not hasattr(session.transport, "prepare_layers"):
        return
    prep = session.layers = LayersPrep(session.transport, scene)

    def layers_ready():  # the panel's line drawn again once they are
        if not prep.done:
            return 0.5
        redraw()
        return None

    bpy.app.timers.register(layers_ready, first_interval=0.5)


def stop_layers(name: str) -> None:
    """The material's layers stopped being made, before another job uses its transport."""
    old = SESSIONS.get(name)
    if old is not None and old.layers is not None:
        old.layers.stop()


def start(material: bpy.types.Material, bl_scene=None, method: str = "prt",
          previous=None, relight: bool = False, pose: bool = False,
          first_preview: bool = False) -> tuple[Job, list[str], export.ExportInfo, dict]:
    """Exports what the material needs and creates (but does not start) the job that builds its
    transport: PRT's precompute (with `relight`, only the lights changed: the `previous`
    session's Prt updated to them, when it was built for the same objects and settings; with
    `pose`, the meshes deformed: that Prt carried to the pose first, `PoseJob`), or the
    hierarchy (updated in place from the `previous` session when the topology is the same).
    `first_preview`: a PRT precompute with Cycles' profile builds a first preview first
    (`Job.first`). Returns the job, the objects, the export info and the lighting keys."""
    bl_scene = bl_scene or bpy.context.scene
    objects = objects_with(material, bl_scene)
    if not objects:
        raise ValueError(f"no mesh object uses material {material.name!r}")
    # An update takes the transport's lock to swap in its result: never while layers are made.
    stop_layers(material.name)
    s = material.translucent
    # PRT with a Principled material keeps the faces of other materials in the mesh, scattering
    # as their own colour (Cycles' walk leaves through them); the others make them occluders.
    scene, info = export.export_scene(objects, bl_scene=bl_scene, material=material,
                                      others_scatter=method == "prt" and s.source == "PRINCIPLED")
    info.skipped_objects = [o.name for o in bl_scene.objects if o.type == "MESH" and o not in objects]
    # A Base Color driven by a link (a texture): read per vertex by Cycles (PRT only), and the
    # transport chosen for the media it spans.
    texture = textures.read(material, info, method)
    materials = texture.materials or [s.material()]
    # The previous session's transport is taken over only when built by this method for the
    # same objects with the same vertex counts.
    def carried(by: str) -> bool:
        return (previous is not None and previous.method == by
                and [(r.name, r.count) for r in previous.info.objects] == [(r.name, r.count) for r in info.objects])

    if method == "splat":
        same = (relight or pose) and carried("splat")
        job = SplatJob(scene, s.material(), (params(s), texture.key), previous=previous.transport if same else None,
                       change="deformation" if pose else "light" if relight else "",
                       profile=s.profile_name(), settings=splat_settings(bl_scene))
    elif method == "hierarchy":
        same = carried("hierarchy")
        job = HierarchyJob(scene, s.material(), previous=previous.transport if same else None,
                           positions=info.positions if same else None, key=(params(s), texture.key),
                           profile=s.profile_name())
    else:
        kwargs = dict(coefficients=s.coefficients, degree=int(s.degree), backend=s.backend, profile=s.profile_name())
        kwargs.update(textures.walked(materials))  # other materials' faces: not walked for
        same = ((relight or pose) and carried("prt") and hasattr(previous.transport, "update")
                and previous.chosen_for == params(s))
        if same and pose:
            job = PoseJob(scene, materials, previous.transport, **kwargs)
        elif same:
            job = RelightJob(scene, materials, previous.transport, **kwargs)
        else:
            # A first preview where the full precompute walks through the mesh (Cycles'
            # profile): shown within a second while the walks run.
            job = Job(scene, materials, first_preview=first_preview and s.profile_name() == "cycles", **kwargs)
    job.method = method
    job.base_color, job.texture_key, job.texture_message = texture.colours, texture.key, texture.message
    job.subsurface_weight, job.others = texture.weights, texture.others
    job.chosen_for = params(s)
    job.profile = s.profile_name()
    # The IOR the transport was built with (the Principled BSDF's where it is followed, even
    # before the panel's fields show it): an edit to another needs a new precompute.
    job.eta = s.material().eta
    return job, [r.name for r in info.objects], info, export.lighting_keys(bl_scene)


def in_background(name: str, job: Job, done, failed, first=None) -> None:
    """Runs `job` for material `name` off the UI thread (headless: here, at once); when it is
    done, `done(material)` swaps its transport in (until then the old preview stays up), or
    `failed(error)` reports its error. `first(material)`: the job's first preview shown as soon
    as it has one (`Job.first`; headless, just before `done`)."""
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
        show_first(mat)
        done(mat)

    shown = []

    def show_first(mat) -> None:
        if first is not None and job.first is not None and not shown:
            shown.append(True)
            first(mat)

    if headless():
        job.run_here()
        complete()
        return

    def poll():
        if not job.done:
            mat = bpy.data.materials.get(name)
            if mat is not None and job.first is not None and not shown:
                show_first(mat)
                redraw()
            return 0.2
        complete()
        redraw()
        return None

    job.start()
    bpy.app.timers.register(poll, first_interval=0.2)


def headless() -> bool:
    """No UI to keep responsive (tests may pretend there is one)."""
    return bpy.app.background


def redraw() -> None:
    """Every area of every window drawn again (what a job or the follow check left changed)."""
    wm = getattr(bpy.context, "window_manager", None)
    for window in wm.windows if wm is not None else ():
        for area in window.screen.areas:
            area.tag_redraw()
