"""A light dragged over a PRT preview, followed at the hierarchy's pace (issue 29, point 5).

PRT's `update(lights=...)` relights its whole transport (2.1 s on the 10 cm bunny, 2-core Xeon),
so a drag would step every two seconds. Once a PRT preview with the walks is shown, a hierarchy
is built beside it on a worker thread from the precompute's own walks' term and own light
(`translucent.Hierarchy(walks_from=prt)`: no walk traced, about 1 s on the bunny). While a light
is dragged, each step is that hierarchy updated to the lights and evaluated (0.25-0.35 s on the
bunny from the change to the preview written, 1.2-1.3 % from a fresh precompute), the panel
saying "relit (dragging)". Once
the light has been still for `follow.DEBOUNCE_S`, PRT relights as before ("relit") and edits go
on from it. With a UI only: a script's `update` relights PRT; and not where the material's
faces lie beside other materials' (the hierarchy does not scatter through those), nor for the
dipole (no walks), where PRT relights at every step as before."""

from __future__ import annotations

import dataclasses
import threading
import time

import bpy
import numpy as np

from . import export, jobs
from .session import SESSIONS, params


class DragPrep:
    """The hierarchy a drag is followed with, built on a worker thread from a shown PRT
    transport (`Hierarchy(walks_from=prt)`, "render" mode: its links kept, so a new light
    gathers over them). `message`: what the panel says of it; `stop()` ends it at its next
    progress call."""

    def __init__(self, session, scene, material: bpy.types.Material):
        self.hierarchy = None
        # What it was built for: the material (`key`: after an edit it is built again rather
        # than evaluated for another material in a drag step, its links summed again or walks
        # for media the carried ones do not cover: seconds) and the export (`fits`).
        self.key = key_of(material, session)
        self.info = session.info
        self.message = "preparing the light drag"
        self.scene = scene
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(session.transport, scene,
                                                                 material.translucent.material()), daemon=True)
        self._thread.start()

    def fits(self, info) -> bool:
        """Whether an export `info` has the objects, vertex counts, positions and occluders of
        the one it was built for (a pose or a moved prop: built again, so that its walks and
        shadows are those of the transport now)."""
        def counts(i):
            return [(r.name, r.count) for r in i.objects]

        return (counts(info) == counts(self.info) and info.occluder_keys == self.info.occluder_keys
                and np.array_equal(info.positions, self.info.positions))

    def _run(self, prt, scene, material):
        import translucent

        try:
            t0 = time.perf_counter()
            self.hierarchy = translucent.Hierarchy(
                scene, material, mode="render", eps=jobs.HIERARCHY_EPS, world_shadows=True,
                estimate_receivers=jobs.HIERARCHY_ESTIMATE_RECEIVERS, walks_from=prt,
                progress=lambda f: not self._stop.is_set())
            self.message = (f"light drag ready ({time.perf_counter() - t0:.1f} s): a dragged light is followed "
                            "by the hierarchy with the precompute's walks, then PRT relights")
        except translucent.Cancelled:
            self.message = ""
        except Exception as e:  # noqa: BLE001 - the panel says it; PRT follows the drag instead
            self.message = f"the light drag was not prepared ({e}): PRT relights at each step"

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=60)

    @property
    def ready(self) -> bool:
        return not self._thread.is_alive() and self.hierarchy is not None


def key_of(material: bpy.types.Material, session) -> tuple:
    """The material a drag's hierarchy is evaluated for: `session.params` and the texture's key."""
    return params(material.translucent), session.texture_key


def prepare(session, scene, material: bpy.types.Material, old=None) -> None:
    """With a UI, the drag's hierarchy for the session's PRT transport (with walks): the old
    session's where it was built for the same material and export (`DragPrep.fits`), else made
    in the background."""
    if jobs.headless() or session.method != "prt" or scene is None or session.others is not None:
        return
    report = session.transport.report
    if session.profile != "cycles" or not report.get("walks"):
        return
    kept = old.drag if old is not None else None
    if (kept is not None and not kept._stop.is_set() and kept.key == key_of(material, session)
            and kept.fits(session.info)):
        session.drag = kept
        return
    if kept is not None:
        kept.stop()
    prep = session.drag = DragPrep(session, scene, material)

    def drag_ready():  # the panel's line drawn again once it is
        if prep._thread.is_alive():
            return 0.5
        jobs.redraw()
        return None

    bpy.app.timers.register(drag_ready, first_interval=0.5)


class DragJob(jobs.Job):
    """One drag step on a worker thread: the drag's hierarchy updated to the lights of `scene`
    and evaluated for the material (its Base Color and Subsurface Weight per vertex where the
    session reads them). `colors`, `last_eval` and `seconds` for the write."""

    label = "Following the light"

    def __init__(self, hierarchy, scene, material, per_vertex: dict):
        super().__init__(scene, [material])
        self._hierarchy, self._material, self._per_vertex = hierarchy, material, per_vertex
        self.colors = self.last_eval = None
        self.seconds = 0.0

    def _run(self, scene, materials, kwargs):
        try:
            t0 = time.perf_counter()
            self._hierarchy.update(lights=scene)
            self.colors = self._hierarchy.radiance(self._material, progress=self._tick, **self._per_vertex)
            self.last_eval = dict(self._hierarchy.last_eval)
            self.seconds = time.perf_counter() - t0
            self.result = self._hierarchy
        except BaseException as e:  # noqa: BLE001 - reported by `follow`'s failure path
            self.error = e


def follow(mat: bpy.types.Material, s, settled) -> bool:
    """A drag step for material `mat` whose lights alone changed, where its drag's hierarchy is
    ready: started on a worker thread (returns True), the colours written when it is done and
    `settled(name)` called so that PRT relights once the light is still. False where the drag
    path does not apply (PRT relights instead)."""
    prep = s.drag
    if prep is None or not prep.ready or s.deformed or s.members_changed or s.occluders_changed:
        return False
    if prep.key != key_of(mat, s):
        # The material was edited since: built again for it in the background; PRT relights
        # this step.
        s.drag = None
        prepare(s, prep.scene, mat)
        return False
    if any(bpy.data.objects.get(n) is None for n in s.objects):
        return False
    bl_scene = bpy.context.scene
    if not (s.info.emitters or s.info.emissive_meshes or s.info.emissive_rectangles):
        # The meshes and occluders as they were (checked above): only the lights and the
        # world read again (an export of the meshes took 0.06 s of a step on the bunny).
        scene = prep.scene.without_lights()
        info = dataclasses.replace(s.info, lights=[], skipped_lights=[], linking=[], unlinked_lights=[])
        export.add_lights(scene, bl_scene, info)
        export.set_world(scene, bl_scene, info)
    else:  # emitters are lights made at the export: exported again
        objects = [o for o in (bpy.data.objects.get(n) for n in s.objects) if o is not None]
        if len(objects) != len(s.objects):
            return False
        scene, info = export.export_scene(objects, bl_scene=bl_scene, material=mat)
        if not prep.fits(info):
            return False
    per_vertex = {k: v for k, v in (("base_color", s.base_color), ("subsurface_weight", s.subsurface_weight))
                  if v is not None}
    job = DragJob(prep.hierarchy, scene, mat.translucent.material(), per_vertex)
    name = mat.name

    def done(material):
        from . import edits

        if SESSIONS.get(name) is not s or not material.translucent.enabled:
            return  # a new transport came in meanwhile (it is shown), or the preview is off
        edits.write_preview(s, job.colors)
        s.last_eval = job.last_eval
        estimate = job.last_eval["error_estimate"]
        s.last_error = None if estimate is None else list(estimate)
        s.last_seconds = job.seconds
        s.follow_message = (f"relit (dragging): the hierarchy with the precompute's walks in {job.seconds:.2f} s; "
                            "PRT relights once the light is still")
        settled(name)

    def failed(error):
        if SESSIONS.get(name) is s:
            s.follow_message = f"the light drag failed ({error}): PRT relights"
            s.drag = None
        settled(name)

    jobs.in_background(name, job, done, failed)
    return True
