"""Following the scene and the view: a depsgraph handler notes a previewed object deforming or a
light or the world changing; a debounced timer checks and refreshes the transport in the background.

The handler only takes notes (which previewed objects' geometry or transform was tagged; a
changed light or world is compared at once, it is cheap); a timer runs once the scene has been
still for DEBOUNCE_S, evaluates the tagged objects to tell a deformation from the add-on's own
colour writes (those tag the mesh too), and refreshes in the background.

A light being dragged is not waited for: where a light or the world changed and nothing but the
previewed meshes was tagged besides (the add-on's own writes tag them), the check runs
LIGHT_INTERVAL_S after the first change noticed, still or not; if the meshes did not deform, it
relights at once, and the next relight starts as soon as that one is done: the preview follows
the drag at the relight's own pace (`Prt.update`: no walk traced). Over a PRT preview with the
walks, a step is the drag's hierarchy instead (`drag`: the precompute's walks carried, 0.25-0.35 s
a step on the 10 cm bunny where PRT's relight takes 2.1 s), and PRT relights once the light has
been still for DEBOUNCE_S (`settled`). A mesh that did deform sends the check back to waiting
for the scene to be still."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import bpy

from . import bake, drag, edits, export, jobs, textures
from .session import JOBS, PREPARING, SESSIONS, Session, objects_with, view_dependent

DEBOUNCE_S = 0.3
# Light-only changes: how long after the first one the relight starts, dragging or not [s].
LIGHT_INTERVAL_S = 0.05
REST = "\x00the rest of the scene"


@dataclass
class Pending:
    """What the handler noted for a material since its last check."""

    first: float  # clock at the first change noticed
    last: float  # clock at the last one
    # Objects whose geometry may have changed; REST among them: the rest of the scene may have,
    # so the occluders are checked too.
    suspects: set = field(default_factory=set)
    lit: bool = False  # a light or the world changed
    others: bool = False  # something besides the lights and the previewed meshes changed
    # The drag's hierarchy showed the lights (`drag`): PRT relights once they are still; a new
    # light change makes it a drag again.
    settle: bool = False

    @property
    def dragging(self) -> bool:
        """A light change the relight follows at once (see the module's docstring)."""
        return self.lit and not self.others and not self.settle

    def due_in(self, now: float) -> float:
        """Seconds until the check is due (<= 0: due)."""
        if self.dragging:
            return LIGHT_INTERVAL_S - (now - self.first)
        return DEBOUNCE_S - (now - self.last)


# material name -> what was noted
PENDING: dict[str, Pending] = {}
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
    if s.occluders_changed:
        parts.append(s.occluders_changed)
    if lighting:
        parts.append(lighting)
    return ", ".join(parts)


def _note(name: str, objects=(), lit: bool = False, others: bool = True) -> None:
    now = _clock()
    p = PENDING.setdefault(name, Pending(now, now))
    if p.settle and lit:
        p.settle, p.first = False, now  # the light moves again: a drag step, not the settling
    p.last = now
    p.suspects |= set(objects)
    p.lit, p.others = p.lit or lit, p.others or others
    # A timer already waiting runs within DEBOUNCE_S and then comes back as soon as the
    # earliest pending check is due (`follow_tick`'s return).
    if not bpy.app.timers.is_registered(follow_tick):
        bpy.app.timers.register(follow_tick, first_interval=max(0.0, p.due_in(now)))


def _is_lighting(id_) -> bool:
    return (isinstance(id_, (bpy.types.Light, bpy.types.World, bpy.types.Scene))
            or (isinstance(id_, bpy.types.Object) and id_.type == "LIGHT")
            or (isinstance(id_, bpy.types.NodeTree) and id_.bl_idname == "ShaderNodeTree"))


@bpy.app.handlers.persistent
def follow_scene(scene, depsgraph) -> None:
    """depsgraph_update_post: notes which objects deformed or moved (geometry or transform
    tagged: armature, shape keys, modifiers, edit mode; a previewed object, or a prop that
    shadows it) and whether a light or the world changed, and schedules the debounced check.
    Evaluates no mesh."""
    if not SESSIONS or bake.BAKING:
        return  # nothing previewed, or the Base Color bake's own temporary data
    tagged, lighting, linked = set(), False, False
    for u in depsgraph.updates:
        id_ = u.id.original
        if _is_lighting(id_):
            lighting = True
        elif isinstance(id_, bpy.types.Object) and (u.is_updated_geometry or u.is_updated_transform):
            tagged.add(id_.name)
        # Objects linked, unlinked or given a material: which objects carry it may differ; a
        # material or its nodes edited: what an occluder sends back may have.
        linked = linked or isinstance(id_, (bpy.types.Scene, bpy.types.Collection, bpy.types.Material,
                                            bpy.types.NodeTree))
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
        # Another object moved, deformed, linked or unlinked: it may shadow differently.
        others = linked or tagged is None or bool(tagged - moved)
        lit = ""
        if keys is not None:
            lit = _lighting_difference(s.lighting, keys)
            s.changed = _describe(s, lit)  # the panel says "stale" at once; geometry after the check
        if moved or lit or others:
            _note(name, moved | {REST} if others else moved, lit=bool(lit), others=others)


def follow_again(material: bpy.types.Material) -> None:
    """Following was switched on (or the preview on again): check every previewed object and
    the lights once the timer runs, and refresh what changed meanwhile."""
    s = SESSIONS.get(material.name)
    if s is not None:
        _note(material.name, s.objects)


def follow_tick() -> float | None:
    """The timer: once a material's scene has been still for DEBOUNCE_S (LIGHT_INTERVAL_S after
    the first light change, still or not: `Pending.due_in`), `follow_now` for it. Returns when
    to run again (None: nothing pending)."""
    now = _clock()
    due = [n for n, p in PENDING.items() if p.due_in(now) <= 0.0]
    follow_now(due, dragging={n for n in due if PENDING[n].dragging and now - PENDING[n].last < DEBOUNCE_S})
    if not PENDING:
        return None
    return max(LIGHT_INTERVAL_S, min(p.due_in(now) for p in PENDING.values()))


def follow_now(names=None, dragging: set = frozenset()) -> None:
    """Checks what the handler noted (all pending materials, or `names`) and refreshes the
    transport of those that changed, in the background: PRT again, or the hierarchy (see
    `jobs.resolve_method`). A material whose job still runs stays pending: checked when it is done.
    `dragging`: materials checked while a light is still changing; where a mesh deformed too,
    they go back to waiting for the scene to be still."""
    for name in list(PENDING if names is None else names):
        if name not in PENDING or name in JOBS or name in PREPARING:
            continue
        pending = PENDING.pop(name)
        suspects = pending.suspects
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
        if name in dragging and s.deformed:
            pending.others = True  # a deformation as well: debounced as one
            PENDING[name] = pending
            continue
        settings = mat.translucent
        if s.changed and settings.enabled and settings.follow_scene:
            # A light still moving over a PRT preview: a step of the drag's hierarchy, PRT
            # relighting once the light is still (`drag`).
            if name in dragging and drag.follow(mat, s, settled):
                continue
            _follow_refresh(mat, s)


def settled(name: str) -> None:
    """The drag's hierarchy showed material `name`'s lights: PRT relights once they have been
    still for DEBOUNCE_S (unless the light moves again first: another drag step)."""
    now = _clock()
    p = PENDING.get(name)
    if p is None:  # else what was noted meanwhile (the light moved on: the next step) stays
        p = PENDING[name] = Pending(now, now, lit=True, settle=True)
    if not bpy.app.timers.is_registered(follow_tick):
        bpy.app.timers.register(follow_tick, first_interval=max(0.0, p.due_in(now)))


def _check(s: Session, mat: bpy.types.Material, suspects: set, bl_scene) -> None:
    """Compares the tagged objects' evaluated geometry, which objects carry the material, the
    occluders (when `REST` is among the suspects), and the lights and world with what the
    transport was built from, and keeps the result on the session (`deformed`,
    `members_changed`, `occluders_changed`, `changed`)."""
    members = {o.name for o in objects_with(mat, bl_scene)}
    # An object holding the material on none of its faces was left out of the export on purpose.
    gained = sorted(members - set(s.objects) - set(s.info.without_faces))
    lost = sorted(set(s.objects) - members)
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
        elif not export.same_topology(key, r.geometry_key):
            s.deformed[r.name] = "topology"
        else:
            s.deformed[r.name] = "deformed"
    if REST in suspects:
        s.occluders_changed = _lighting_difference(s.info.occluder_keys, export.occluder_keys(depsgraph, set(s.objects)))
    s.changed = _describe(s, _lighting_difference(s.lighting, export.lighting_keys(bl_scene)))


def _follow_refresh(mat: bpy.types.Material, s: Session) -> None:
    """Builds the transport again for the scene as it is now, in the background; the old
    preview stays up until the new one is written. A topology change always starts from
    scratch; the hierarchy updates itself in place otherwise."""
    change = "deformation" if s.deformed else "light"
    method, message = jobs.resolve_method(mat.translucent.method, change, s.method)
    topology = any(v != "deformed" for v in s.deformed.values()) or bool(s.members_changed)
    name = mat.name
    try:
        job, objects, info, lighting = jobs.start(mat, method=method, previous=None if topology else s,
                                                  relight=change == "light" and not topology,
                                                  pose=change == "deformation" and not topology)
    except ValueError as e:
        s.follow_message = f"following the scene failed: {e}"
        return
    s.follow_message = f"refreshing ({jobs.METHOD_NAMES[method]}): {s.changed}"

    def failed(error):
        cur = SESSIONS.get(name)
        if cur is not None:
            cur.follow_message = f"following the scene failed: {error}"

    def hierarchy_failed(error):
        # When the hierarchy fails, PRT keeps the preview following, saying why.
        material = bpy.data.materials.get(name)
        if material is None:
            return
        why = f"hierarchy failed ({error}), PRT used"
        try:
            job2, objects2, info2, lighting2 = jobs.start(material, method="prt")
        except ValueError as e:
            failed(e)
            return
        edits.in_background(name, job2, objects2, info2, lighting2, failed, why)

    def refine(mat):
        # The hierarchy carried its walks to the pose: now it walks the pose, in the background.
        if getattr(job, "retrace", False) and mat.name not in JOBS:
            again = jobs.RetraceJob(job.result, mat.translucent.material())
            for key in ("method", "base_color", "subsurface_weight", "others", "texture_key", "texture_message",
                        "chosen_for", "profile", "key"):
                setattr(again, key, getattr(job, key, None))
            edits.in_background(mat.name, again, objects, info, lighting, failed, message)

    edits.in_background(name, job, objects, info, lighting, hierarchy_failed if method == "hierarchy" else failed,
                        message, then=refine)


# ----------------------------------------------------------------------- following the view
#
# How far the eye must move, relative to its distance from the origin plus 1 unit, before the
# view-dependent preview is drawn again; and how often the viewport's view is looked at [s].
EYE_TOLERANCE = 1e-3
VIEW_POLL_S = 0.2


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
    edits.edit(material)
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
