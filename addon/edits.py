"""Material edits: a finished job's transport shown, and each edit (a slider, a Principled
input) refitted, evaluated and written back; a refresh when it leaves the basis' range."""

from __future__ import annotations

import threading

import bpy
import numpy as np

from . import bake, drag, export, jobs, textures, viewport, writeback
from .principled import principled_key, show_medium
from .session import JOBS, PREPARING, SESSIONS, Session, objects_with, params, view_dependent


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
        if obj is None or r.name not in objects or len(obj.data.vertices) == r.evaluated_count:
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


def finish(material: bpy.types.Material, job: jobs.Job, objects, info, lighting, method_message: str = "") -> Session:
    """The finished job's transport becomes the material's session (the old one, still shown
    until now, is dropped) and the preview is written from it."""
    session = Session(job.result, info, objects, lighting, getattr(job, "eta", material.translucent.eta),
                      profile=job.profile)
    session.chosen_for = job.chosen_for
    session.method = getattr(job, "method", "prt")
    session.method_message = method_message
    # What the follow refresh did ("relit: ... no walk traced"), for the panel.
    session.follow_message = getattr(job, "stage_message", "")
    session.remap = nearest_original_vertices(objects, info)
    _take_texture(session, job)
    if getattr(job, "colors", None) is not None:
        # The splatting's or the hierarchy's evaluation, made on the worker.
        session.evaluated, session.report = (job.key, job.colors, job.last_eval), job.report
    jobs.stop_layers(material.name)
    old = SESSIONS.get(material.name)
    SESSIONS[material.name] = session
    edit(material)
    viewport.show([o for o in (bpy.data.objects.get(n) for n in objects) if o is not None])
    jobs.prepare_layers(session, getattr(job, "scene", None))
    drag.prepare(session, getattr(job, "scene", None), material, old)
    return session


def _evaluated(material: bpy.types.Material, s: Session):
    """Method = Splatting or Hierarchy, whose every edit evaluates again (the splatting splats
    the scene, the hierarchy sums its links: seconds): the radiance for the material as it is
    now, when the session's last evaluation was for it; else None, and it is evaluated for it on
    a worker thread (headless: at once), the edit shown when that is done. The old preview stays
    meanwhile. An edit made while one is evaluated cancels it (`jobs.EditJob.supersedable`) and
    runs when it has stopped; while the transport is refreshed (a light, a pose), after that."""
    key = (params(material.translucent), s.texture_key)
    if s.evaluated is not None and s.evaluated[0] == key:
        return s.evaluated[1]
    name = material.name
    running = JOBS.get(name)
    if running is not None:
        if getattr(running, "supersedable", False) and running.key != key:
            running.cancel = True  # overtaken: it stops at its next progress call
        return None  # its end runs this edit again
    m = material.translucent.material()
    if s.method == "splat":
        job = jobs.SplatJob(None, m, key, previous=s.transport)
        job.supersedable, job.label = True, "Splatting the edit in the background"
        s.edit_message = "splatting the edit in the background (nothing precomputed)"
    else:
        job = jobs.EditJob(s.transport, m, key)
    # A Base Color read per vertex (media blended around it) and, for the hierarchy, the weight.
    job.base_color, job.subsurface_weight = s.base_color, s.subsurface_weight

    def done(mat):
        if SESSIONS.get(name) is s:
            s.evaluated, s.report = (job.key, job.colors, job.last_eval), job.report
            s.edit_message = ""
            edit(mat)

    def failed(error):
        mat = bpy.data.materials.get(name)
        if SESSIONS.get(name) is not s or mat is None:
            return
        if job.cancel:
            s.edit_message = ""
            edit(mat)  # overtaken by a later edit: that one evaluated now
        else:
            s.edit_message = f"not shown: {error}"

    jobs.in_background(name, job, done, failed)
    return None


def _take_texture(session: Session, job: jobs.Job) -> None:
    """The Base Color and Subsurface Weight the job read per vertex (`jobs.start`), kept with
    the session."""
    session.base_color = getattr(job, "base_color", None)
    session.subsurface_weight = getattr(job, "subsurface_weight", None)
    session.others = getattr(job, "others", None)
    session.texture_key = getattr(job, "texture_key", "")
    session.texture_message = getattr(job, "texture_message", "")


def follow_texture(material: bpy.types.Material, s: Session, force: bool = False) -> None:
    """Read the Base Color per vertex again when what it depends on changed
    (`textures.reading_key`: the node tree's key, the Base Color beside other materials' faces;
    or `force`: an image it reads was edited), when a link now drives it, or drop it when none
    does. Every method (the hierarchy and the splatting blend media around each vertex's
    colour)."""
    key = textures.reading_key(material, s.info, s.method)
    if key and not force and key == s.texture_key:
        return
    texture = textures.read(material, s.info, s.method)
    s.base_color, s.texture_key, s.texture_message = texture.colours, texture.key, texture.message
    s.subsurface_weight, s.others = texture.weights, texture.others


FIRST_PREVIEW_MESSAGE = "first preview after {:.2f} s (no walks yet): refining with the walks"


def show_first(material: bpy.types.Material, job: jobs.Job, objects, info, lighting) -> Session | None:
    """The job's first preview (`jobs.Job.first`) shown while its full precompute runs: a
    session of its own (edits work on it), replaced by `finish` when the job is done. None
    when the job has none (yet)."""
    if job.first is None:
        return None
    session = Session(job.first, info, objects, lighting, getattr(job, "eta", material.translucent.eta),
                      profile=job.profile)
    session.chosen_for = job.chosen_for
    session.method = getattr(job, "method", "prt")
    session.method_message = getattr(job, "first_message", "") or FIRST_PREVIEW_MESSAGE.format(job.first_seconds)
    session.remap = nearest_original_vertices(objects, info)
    _take_texture(session, job)
    if getattr(job, "first_colors", None) is not None:
        # The splatting's carried pose (the job goes on with the same Splat: its report is busy).
        session.evaluated, session.report = (job.key, job.first_colors, job.first_eval), job.first_report
    SESSIONS[material.name] = session
    edit(material)
    viewport.show([o for o in (bpy.data.objects.get(n) for n in objects) if o is not None])
    return session


def in_background(name: str, job: jobs.Job, objects, info, lighting, failed, method_message: str = "",
                  then=None) -> None:
    """`job` run off the UI thread (`jobs.in_background`); its transport is shown when done, and
    its first preview (a pose carried, `jobs.PoseJob`) as soon as it has one. `then(material)`
    runs after the transport is shown (a refinement to start)."""
    def done(mat):
        finish(mat, job, objects, info, lighting, method_message)
        if then is not None:
            then(mat)

    jobs.in_background(name, job, done, failed, first=lambda mat: show_first(mat, job, objects, info, lighting))


def _previewed(material: bpy.types.Material) -> list[bpy.types.Object]:
    sess = SESSIONS.get(material.name)
    return [o for o in (bpy.data.objects.get(n) for n in sess.objects) if o is not None] if sess else []


def preview_on(material: bpy.types.Material) -> bool:
    """The preview turned on again: the transport, if there is one, shown (returns whether)."""
    if material.name not in SESSIONS:
        return False
    edit(material)
    viewport.show(_previewed(material))
    return True


def preview_off(material: bpy.types.Material) -> None:
    """The preview turned off: the viewports and active colour attributes put back."""
    viewport.restore(_previewed(material) or objects_with(material))


def edit(material: bpy.types.Material) -> None:
    """Refit and re-evaluate the material, and write every object's preview attribute."""
    import translucent

    s = SESSIONS.get(material.name)
    if s is None or not material.translucent.enabled:
        return
    settings = material.translucent
    if settings.source == "PRINCIPLED":
        follow_texture(material, s)
        # After the reading: a linked Radius or Scale read again moves the inputs' mean.
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
    if s.profile in ("dipole", "multipole") and abs(s.eta - m.eta) > 1e-9:
        return  # the irradiance holds the IOR's Fresnel factor (dipole, multipole): precompute again
    if s.profile != "dipole" and not translucent.profile_ready(m, s.profile) and not _prepare_tables(material, m):
        return  # the tables for a new g, Roughness, IOR or layer are being built; old preview kept
    s.edit_message = ""
    transport = s.transport
    # Radiance leaving along each normal (a view-independent viewport colour), or toward the
    # viewport's eye where single scattering makes it depend on the view.
    # A Base Color read per vertex (`follow_texture`): each vertex scatters as its own medium.
    if s.method in ("splat", "hierarchy"):
        colors = _evaluated(material, s)
        if colors is None:
            return  # evaluated on a worker thread: this edit runs again when it is done
        s.last_eval = dict(s.evaluated[2])
    else:
        textured = textures.Reading(colours=s.base_color, weights=s.subsurface_weight, others=s.others).kwargs()
        try:
            eye = s.eye if s.eye is not None and view_dependent(s) else None
            colors = transport.radiance(m, eye, **textured)
        except ValueError as e:
            s.edit_message = f"not shown: {e}"
            return
        # The method's own evaluation (the keys every method reports), kept as it gave it.
        s.last_eval = dict(transport.last_eval)
    estimate = s.last_eval["error_estimate"]
    s.last_error = None if estimate is None else list(estimate)
    s.last_seconds = s.last_eval["seconds"]
    s.refresh_advised = bool(s.last_eval["refresh_advised"])
    write_preview(s, colors)
    if s.refresh_advised:
        refresh(material)


def write_preview(s: Session, colors) -> None:
    """Every previewed object's preview attribute written from `colors` (per exported vertex),
    and what could not be written kept for the panel (`not_shown`)."""
    s.not_shown = []
    users: dict[str, list[str]] = {}  # mesh name -> the objects written into it, in order
    for name, values in writeback.per_object(colors, s.info).items():
        obj = bpy.data.objects.get(name)
        if obj is None:
            continue
        users.setdefault(obj.data.name, []).append(name)
        if not obj.data.is_editable:
            # Linked library data is read-only: never written, the panel says how to see it.
            lib = obj.data.library.filepath if obj.data.library is not None else "a library"
            s.not_shown.append(f"{name}: its mesh is linked from {lib} (read-only); make it local or a "
                               "library override to see the preview")
        elif len(obj.data.vertices) == len(values):
            writeback.write_colors(obj.data, values)
        elif name in s.remap and len(s.remap[name]) == len(obj.data.vertices):
            writeback.write_colors(obj.data, values[s.remap[name]])
        else:
            # The mesh changed since the precompute: the attribute cannot hold the values.
            s.not_shown.append(f"{name}: mesh changed since the precompute, not shown")
    for mesh, names in users.items():
        if len(names) > 1:
            # Linked duplicates (Alt+D): one mesh, one attribute, the last object's light in it.
            s.not_shown.append(f"{len(names)} objects share the mesh {mesh}: it shows {names[-1]}'s preview "
                               "(Object > Relations > Make Single User to see each)")


def _prepare_tables(material: bpy.types.Material, m) -> bool:
    """The profile's tables for `m`: Cycles' walk tables (a new g, Roughness or IOR) or the
    multipole's layered tables (a new top layer or depth, about 2 s): built at once headless
    (returns True, or False with the reason in the panel), else on a worker thread that never
    touches bpy, the edit running again when they are ready (returns False; the old preview
    stays up meanwhile)."""
    import translucent

    name = material.name
    s = SESSIONS[name]
    profile = s.profile
    if bpy.app.background:
        try:
            translucent.prepare_profile(m, profile=profile)
        except ValueError as e:
            s.edit_message = f"not shown: {e}"
            return False
        return True
    if name in PREPARING:
        return False
    if profile == "cycles":
        s.edit_message = f"building Cycles' walk table (g {m.g:.2f}, Roughness {m.roughness:.2f}, IOR {m.eta:.2f})"
    else:
        s.edit_message = "building the multipole's layer table"
    errors = []

    def work():
        try:
            translucent.prepare_profile(m, profile=profile)
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
            jobs.redraw()
        return None

    bpy.app.timers.register(poll, first_interval=0.2)
    return False


@bpy.app.handlers.persistent
def follow_principled(_scene=None, depsgraph=None) -> None:
    """depsgraph_update_post: a previewed material that follows its Principled BSDF is shown
    again when any input it reads has changed (cheap when none did), its Base Color read again
    when what drives it changed (`follow_texture`)."""
    if bake.BAKING:
        return  # the bake's own temporary data
    for name, s in list(SESSIONS.items()):
        mat = bpy.data.materials.get(name)
        if mat is None or not mat.translucent.enabled or mat.translucent.source != "PRINCIPLED":
            continue
        images = textures.images_of(mat) if s.texture_key else set()
        painted = bool(images) and any(isinstance(u.id.original, bpy.types.Image) and u.id.original.name in images
                                       for u in getattr(depsgraph, "updates", ()))
        if painted:
            follow_texture(mat, s, force=True)
        if (painted or principled_key(mat) != s.principled_key
                or (s.method in ("prt", "hierarchy", "splat") and _texture_changed(mat, s))):
            edit(mat)


def _texture_changed(mat: bpy.types.Material, s: Session) -> bool:
    """A link now drives the Base Color or the Subsurface Weight, or no longer does, or what
    drives them changed, or the Base Color beside other materials' faces did
    (`textures.reading_key`)."""
    return textures.reading_key(mat, s.info, s.method) != s.texture_key


def refresh(material: bpy.types.Material) -> None:
    """The edit left the range the basis and samples were chosen for (the error estimate says
    so): precompute again for the current material in the background and swap the transport
    in when it is done; the preview keeps showing, flagged by the panel, meanwhile. Headless,
    it runs at once. Nothing happens while a job runs, or when the transport was already chosen
    for these very settings (no loop)."""
    s = SESSIONS.get(material.name)
    if s is None or material.name in JOBS or not material.translucent.auto_refresh:
        return
    if s.chosen_for == params(material.translucent):
        return
    try:
        job, objects, info, lighting = jobs.start(material, method=s.method)
    except ValueError as e:
        s.refresh_message = f"refresh failed: {e}"
        return
    s.refresh_message = "refreshing the basis for the new material"

    def failed(error):
        cur = SESSIONS.get(material.name)
        if cur is not None:
            cur.refresh_message = f"refresh failed: {error}"

    in_background(material.name, job, objects, info, lighting, failed)
