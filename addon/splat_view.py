"""The splatting's camera image (Shah 2009, issue 31): every previewed material of the scene
rendered by `translucent.Splat.render` from a camera or the 3D viewport's view, the materials'
images put together by their object masks (each material's render hides the others' objects,
so no pixel is shown twice and no light passes between them), written into the add-on's own
image `IMAGE` and drawn over the 3D viewports while the scene's "Show in viewport" is on.

Under Cycles' profile the image has the walks' geometry term and the object's own light
(`Splat(walks=True)`): walked at a material's first render and carried to a new light or pose
after, its `Splat` kept between renders (`SPLATS`).

While it is on, the image follows by itself: a moved light, a deformed or animated mesh, a
material edit or a new viewport view changes the scene's key (`state_key`: the view, each
material's settings, its objects' and occluders' geometry keys, the lights and the world), and
the next `tick` renders it again on a worker thread (headless: at once) while the old image
stays up. Nothing is rendered when the key is unchanged, so the preview's own colour writes
never re-render it. The image is written only into `IMAGE`; nothing of the user's is touched."""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field

import bpy
import numpy as np

from . import export, jobs, principled
from .session import objects_with, params

IMAGE = "Translucent Splatting"
POLL_S = 0.25


@dataclass(frozen=True)
class View:
    """A pinhole: `eye` looking at `target`, `up` the image's up, `fov` [rad] across the larger
    side of `size` = (width, height) pixels (Blender's camera angle with sensor fit Auto)."""

    eye: tuple
    target: tuple
    up: tuple
    fov: float
    size: tuple

    def key(self) -> tuple:
        r = lambda v: tuple(round(float(x), 6) for x in v)  # noqa: E731
        return (r(self.eye), r(self.target), r(self.up), round(self.fov, 6), tuple(self.size))


def _frame(matrix) -> tuple:
    """Eye, a target one unit ahead (-Z) and up (+Y) of an object's or a view's world matrix."""
    m = np.array(matrix, dtype=np.float64)
    eye = m[:3, 3]
    forward = -m[:3, 2] / np.linalg.norm(m[:3, 2])
    up = m[:3, 1] / np.linalg.norm(m[:3, 1])
    return tuple(eye), tuple(eye + forward), tuple(up)


def camera_view(camera: bpy.types.Object, bl_scene: bpy.types.Scene, size: tuple | None = None) -> View:
    """The view of `camera` (a perspective camera object) at `size`, or the scene's render
    resolution times its percentage. ValueError naming the camera otherwise."""
    if camera is None or camera.type != "CAMERA":
        raise ValueError(f"camera: {getattr(camera, 'name', None)!r} is not a camera object")
    if camera.data.type != "PERSP":
        raise ValueError(f"camera {camera.name!r} is {camera.data.type.lower()}: the splatting image needs a "
                         "perspective camera")
    if camera.data.sensor_fit != "AUTO":
        raise ValueError(f"camera {camera.name!r}: sensor fit {camera.data.sensor_fit.title()} is not supported "
                         "(set it to Auto)")
    if size is None:
        r = bl_scene.render
        k = r.resolution_percentage / 100.0
        size = (max(1, round(r.resolution_x * k)), max(1, round(r.resolution_y * k)))
    eye, target, up = _frame(camera.matrix_world)
    return View(eye, target, up, float(camera.data.angle), tuple(int(x) for x in size))


def region_view(region, rv3d, max_side: int) -> View | None:
    """The view a 3D viewport region shows, at its aspect, its larger side at most `max_side`
    pixels; None for an orthographic view (the splatting renders a pinhole)."""
    if not rv3d.is_perspective or region.width < 1 or region.height < 1:
        return None
    w = np.array(rv3d.window_matrix, dtype=np.float64)
    # A perspective projection's diagonal holds 1 / tan(half angle) across each side; the
    # larger side has the wider angle.
    fov = 2.0 * math.atan(1.0 / min(w[0, 0], w[1, 1]))
    scale = min(1.0, max_side / max(region.width, region.height))
    size = (max(1, round(region.width * scale)), max(1, round(region.height * scale)))
    eye, target, up = _frame(np.linalg.inv(np.array(rv3d.view_matrix, dtype=np.float64)))
    return View(eye, target, up, fov, size)


def materials_in(bl_scene: bpy.types.Scene) -> list[bpy.types.Material]:
    """The previewed materials (preview on) that some mesh object of the scene uses."""
    seen = []
    for o in bl_scene.objects:
        if o.type != "MESH":
            continue
        for slot in o.material_slots:
            m = slot.material
            if m is not None and m.translucent.enabled and m not in seen:
                seen.append(m)
    return seen


def state_key(bl_scene: bpy.types.Scene, view: View, materials) -> tuple:
    """What the image depends on, to compare: the view, and per material its settings, what
    drives a linked Base Color and the geometry of its objects and of the rest of the scene, the
    lights and the world."""
    from . import textures

    depsgraph = bpy.context.evaluated_depsgraph_get()
    parts = [view.key(), tuple(sorted(export.lighting_keys(bl_scene).items())),
             bl_scene.translucent_splat.eps, bl_scene.translucent_splat.max_grid, bl_scene.translucent_splat.backend]
    everything = set()
    for mat in materials:
        objects = objects_with(mat, bl_scene)
        everything.update(o.name for o in objects)
        texture = textures.tree_key(mat) if textures.linked(mat, "Base Color") else ""  # followed
        parts.append((mat.name, params(mat.translucent), mat.translucent.profile, texture,
                      tuple(export.object_geometry_key(o, depsgraph) for o in objects)))
    parts.append(tuple(sorted(export.occluder_keys(depsgraph, everything).items())))
    return tuple(parts)


@dataclass
class Rendered:
    """The last image: radiance (H, W, 3) row 0 the top, the object seen per pixel (index into
    `objects` plus 1; 0 none), what it was rendered for, and each material's report."""

    radiance: np.ndarray
    mask: np.ndarray
    objects: list
    view: View
    key: tuple
    seconds: float
    reports: dict = field(default_factory=dict)


# The vertices each render reads the ground truth at for its error estimate: half the API's
# default, so a dragged light waits about a second less for its image on the 10 cm bunny.
ESTIMATE_RECEIVERS = 8

# Per material: its `translucent.Splat` and what it was made for, kept between renders so the
# walks' term (Cycles' profile) is walked once and carried to a new light or pose after.
SPLATS: dict = {}
_SPLATS_LOCK = threading.Lock()


def _splat_for(name: str, scene, names: list, profile: str, settings: tuple):
    """The kept Splat of material `name` updated to `scene` (same objects, vertex and triangle
    counts, profile and settings), or a new one: with the walks under Cycles' profile."""
    import translucent

    made_for = (tuple(names), scene.vertex_count, scene.triangle_count, profile, settings)
    with _SPLATS_LOCK:
        kept = SPLATS.get(name)
    positions = np.asarray(scene.positions)
    if kept is not None and kept[1] == made_for:
        splat = kept[0]
        if np.array_equal(kept[2], positions):
            splat.update(lights=scene)  # a pose carries the walks differently: only when posed
        else:
            splat.update(positions=positions, normals=scene.normals, lights=scene)
            with _SPLATS_LOCK:
                SPLATS[name] = (splat, made_for, positions)
        return splat
    eps, max_grid, backend = settings
    # reuse: each render keeps the earlier renders' splat sources that still see the light
    # (Shah 2009's sampling coherence): a dragged light or a turning object does not flicker.
    splat = translucent.Splat(scene, profile=profile, eps=eps, max_grid=max_grid, walks=profile == "cycles",
                              backend=backend.lower(), reuse=True, estimate_receivers=ESTIMATE_RECEIVERS)
    with _SPLATS_LOCK:
        SPLATS[name] = (splat, made_for, positions)
    return splat


class RenderJob(jobs.Job):
    """Each material's splatting rendered on a worker thread that never touches bpy (the scenes
    were exported before); `progress` in [0, 1], `cancel` stops it at the next tick."""

    def __init__(self, parts, view: View, key: tuple, settings: tuple):
        super().__init__(None, [])
        self.parts, self.view, self.key = parts, view, key
        self.settings = settings  # (eps, max_grid, backend)
        self.notes: dict = {}  # per material, what the image does not follow (a `skipped` entry)

    def _run(self, scene, materials, kwargs):
        try:
            t0 = time.perf_counter()
            w, h = self.view.size
            radiance = np.zeros((h, w, 3), np.float32)
            mask = np.zeros((h, w), np.int32)
            objects, reports = [], {}
            for k, (name, scene, names, profile, material, textured) in enumerate(self.parts):
                splat = _splat_for(name, scene, names, profile, self.settings)
                span = (k / len(self.parts), (k + 1) / len(self.parts))

                def tick(f, span=span):
                    self.progress = span[0] + (span[1] - span[0]) * f
                    return not self.cancel

                # A Base Color per vertex: media blended per pixel; a weight: lobes split per corner.
                img, m = splat.render(material, eye=self.view.eye, target=self.view.target, up=self.view.up,
                                      fov=self.view.fov, size=self.view.size, progress=tick, **textured)
                seen = m > 0
                radiance[seen] = img[seen]
                mask[seen] = m[seen] + len(objects)
                objects.extend(names)
                reports[name] = {**splat.last_eval, "report": splat.report}
                if name in self.notes:
                    reports[name]["skipped"] = [*reports[name]["skipped"], self.notes[name]]
            self.result = Rendered(radiance, mask, objects, self.view, self.key, time.perf_counter() - t0, reports)
        except BaseException as e:  # reported by whoever polls the job
            self.error = e


# Per material: the Base Color and Subsurface Weight read per exported vertex for the image,
# and what they were read for (the node tree upstream of them, the exported positions and the
# profile), so a moved light or a new view renders again without a bake.
_COLOURS: dict[str, tuple] = {}


def _per_vertex(mat: bpy.types.Material, info, scene) -> dict:
    """`Splat.render`'s per-vertex arguments: the Base Color (`base_color`) and, with Cycles'
    profile, the Subsurface Weight (`subsurface_weight`) per exported vertex where a link drives
    them (`textures.for_export`, baked by Cycles; read again only when the node tree, the
    geometry or the profile changed); an input that cannot be read is left out (the note then
    names it as not followed)."""
    import hashlib

    from . import textures

    wanted = [k for k, socket, ok in (("base_color", "Base Color", True),
                                      ("subsurface_weight", "Subsurface Weight",
                                       mat.translucent.profile_name() == "cycles"))
              if ok and textures.linked(mat, socket)]
    if not wanted:
        _COLOURS.pop(mat.name, None)
        return {}
    positions = np.ascontiguousarray(np.asarray(scene.positions, np.float32))
    key = (textures.tree_key(mat), hashlib.blake2b(positions.tobytes(), digest_size=16).hexdigest(), tuple(wanted))
    kept = _COLOURS.get(mat.name)
    if kept is not None and kept[0] == key:
        return kept[1]
    out = {}
    for k in wanted:
        try:
            read = textures.for_export if k == "base_color" else textures.weights_for_export
            out[k], _ = read(mat, info)
        except ValueError:
            continue
    _COLOURS[mat.name] = (key, out)
    return out


def prepare(bl_scene: bpy.types.Scene, view: View, materials=None, key: tuple | None = None) -> RenderJob:
    """Exports each material's scene (on this thread: bpy) and returns the job that renders
    them, not started; `key`: the scene's `state_key` where the caller has just computed it.
    ValueError when no previewed material is in the scene."""
    materials = materials_in(bl_scene) if materials is None else materials
    if not materials:
        raise ValueError("no previewed material in the scene: turn the preview on for a material")
    parts, notes = [], {}
    for mat in materials:
        objects = objects_with(mat, bl_scene)
        if not objects:
            continue
        scene, info = export.export_scene(objects, bl_scene=bl_scene, material=mat)
        s = mat.translucent
        textured = _per_vertex(mat, info, scene) if s.source == "PRINCIPLED" else {}
        parts.append((mat.name, scene, [r.name for r in info.objects], s.profile_name(), s.material(), textured))
        connected = principled.connected_inputs(mat) if s.source == "PRINCIPLED" else []
        followed = {"base_color": "Base Color (", "subsurface_weight": "Subsurface Weight ("}
        connected = [c for c in connected if not any(c.startswith(followed[k]) for k in textured)]
        if connected:
            # Said, not shown silently: the image takes the sockets' own values everywhere.
            notes[mat.name] = {"what": "linked inputs: " + ", ".join(connected),
                               "why": "not followed by the splatting image yet: the socket's own value is "
                                      "used everywhere (a linked Base Color and, with Cycles' profile, "
                                      "Subsurface Weight are followed)"}
    if not parts:
        raise ValueError("no mesh object uses a previewed material")
    settings = bl_scene.translucent_splat
    key = state_key(bl_scene, view, materials) if key is None else key
    job = RenderJob(parts, view, key, (settings.eps, settings.max_grid, settings.backend))
    job.notes = notes
    return job


# The last image shown, the job rendering the next one, and the view the viewport asked for.
STATE: dict = {"last": None, "job": None, "wanted": None, "dirty": False, "renders": 0, "message": "",
               "texture": None}


def store(result: Rendered) -> bpy.types.Image:
    """`result` written into the add-on's own image (created or resized; rows bottom-up, alpha
    1 where a previewed object is seen) and kept as the last image."""
    h, w = result.mask.shape
    image = bpy.data.images.get(IMAGE)
    if image is None:
        image = bpy.data.images.new(IMAGE, w, h, alpha=True, float_buffer=True)
    elif tuple(image.size) != (w, h):
        image.scale(w, h)
    rgba = np.concatenate([result.radiance, (result.mask > 0)[..., None].astype(np.float32)], axis=2)
    image.pixels.foreach_set(np.ascontiguousarray(rgba[::-1]).ravel())
    image.update()
    STATE["last"], STATE["texture"] = result, None
    STATE["renders"] += 1
    seconds = sum(r["seconds"] for r in result.reports.values())
    pixels = int((result.mask > 0).sum())
    gpus = sorted({r["report"]["gpu"]["adapter"] for r in result.reports.values() if r["report"].get("gpu")})
    where = f"splats drawn on {', '.join(gpus)}" if gpus else "splats gathered on the CPU"
    STATE["message"] = (f"splatting image: {pixels:,} pixels of {len(result.reports)} material(s) in {seconds:.2f} s"
                        f" ({where})")
    unfollowed = [name for name, r in result.reports.items()
                  if any(x["what"].startswith("linked inputs") for x in r["skipped"])]
    if unfollowed:
        STATE["message"] += f"; textures not followed in {', '.join(unfollowed)}"
    errors = [max(r["error_estimate"]) for r in result.reports.values() if r.get("error_estimate") is not None]
    if errors:
        STATE["message"] += (f"; estimated error up to {100 * max(errors):.1f} % (the ground truth at "
                             f"{ESTIMATE_RECEIVERS} vertices)")
    return image


def save(path: str, bl_scene: bpy.types.Scene) -> None:
    """The image saved to `path` as the scene's output would save it (colour managed; OpenEXR
    linear), without changing the image's own file path."""
    image = bpy.data.images[IMAGE]
    image.save_render(bpy.path.abspath(path), scene=bl_scene)


@bpy.app.handlers.persistent
def follow_depsgraph(scene, depsgraph=None) -> None:
    """Depsgraph and frame handler: something changed; the next `tick` compares the key. The
    image's own update is not a change."""
    if not scene.translucent_splat.show_in_viewport:
        return
    if depsgraph is not None and all(isinstance(u.id, bpy.types.Image) for u in depsgraph.updates):
        return
    STATE["dirty"] = True


def _wanted_view(bl_scene) -> View | None:
    view = STATE.get("wanted")
    if view is not None:
        return view
    return camera_view(bl_scene.camera, bl_scene) if bl_scene.camera is not None else None


def tick() -> float | None:
    """The timer: a finished render shown; a changed key rendered again (off the UI thread; in
    headless Blender at once). Stops when "Show in viewport" is off."""
    bl_scene = bpy.context.scene
    job = STATE["job"]
    if job is not None:
        if not job.done:
            return POLL_S
        STATE["job"] = None
        if job.error is not None:
            STATE["message"] = f"splatting image failed: {job.error}"
        else:
            store(job.result)
        _redraw()
    if not bl_scene.translucent_splat.show_in_viewport:
        return None
    if not STATE["dirty"] and STATE["last"] is not None:
        return POLL_S
    STATE["dirty"] = False
    try:
        view = _wanted_view(bl_scene)
        if view is None:
            STATE["message"] = "splatting image: no scene camera and no perspective viewport to render"
            return POLL_S
        materials = materials_in(bl_scene)
        key = state_key(bl_scene, view, materials) if materials else None
        last = STATE["last"]
        if last is not None and key is not None and last.key == key:
            return POLL_S
        job = prepare(bl_scene, view, materials, key)
    except ValueError as e:
        STATE["message"] = f"splatting image: {e}"
        return POLL_S
    STATE["job"] = job
    if bpy.app.background:
        job.run_here()
        return tick()
    job.start()
    return POLL_S


def settings_changed(settings, context) -> None:
    """A setting of the image changed: the next `tick` compares the key (it holds the settings)."""
    STATE["dirty"] = True


def show_toggle(settings, context) -> None:
    """"Show in viewport" switched: the timer started (the image rendered) or the drawing stopped."""
    if settings.show_in_viewport:
        STATE["dirty"] = True
        if not bpy.app.timers.is_registered(tick):
            bpy.app.timers.register(tick, first_interval=0.0)
    _redraw()


def _redraw() -> None:
    wm = getattr(bpy.context, "window_manager", None)
    for window in wm.windows if wm is not None else ():
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


def draw() -> None:
    """Draw handler (3D viewport, POST_PIXEL): notes the view (a new one is rendered by the
    timer) and draws the last image over the region, display-encoded (sRGB of the clamped
    radiance), transparent where no previewed object is seen."""
    context = bpy.context
    settings = context.scene.translucent_splat
    if not settings.show_in_viewport:
        return
    region, rv3d = context.region, context.region_data
    if region is None or rv3d is None:
        return
    view = region_view(region, rv3d, settings.max_side)
    if view is not None and (STATE["wanted"] is None or STATE["wanted"].key() != view.key()):
        STATE["wanted"], STATE["dirty"] = view, True
    last = STATE["last"]
    if last is None:
        return
    import gpu
    from gpu_extras.presets import draw_texture_2d

    if STATE["texture"] is None:
        h, w = last.mask.shape
        shown = np.clip(last.radiance, 0.0, 1.0) ** (1.0 / 2.2)
        rgba = np.concatenate([shown, (last.mask > 0)[..., None].astype(np.float32)], axis=2)[::-1]
        buf = gpu.types.Buffer("FLOAT", w * h * 4, np.ascontiguousarray(rgba, np.float32).ravel())
        STATE["texture"] = gpu.types.GPUTexture((w, h), format="RGBA16F", data=buf)
    gpu.state.blend_set("ALPHA")
    draw_texture_2d(STATE["texture"], (0, 0), region.width, region.height)
    gpu.state.blend_set("NONE")


_HANDLE: list = []


def register() -> None:
    if not bpy.app.background:
        _HANDLE.append(bpy.types.SpaceView3D.draw_handler_add(draw, (), "WINDOW", "POST_PIXEL"))


def unregister() -> None:
    while _HANDLE:
        bpy.types.SpaceView3D.draw_handler_remove(_HANDLE.pop(), "WINDOW")
    if bpy.app.timers.is_registered(tick):
        bpy.app.timers.unregister(tick)
    forget()


def forget() -> None:
    """A new file: no image of its own yet."""
    STATE.update(last=None, job=None, wanted=None, dirty=False, renders=0, message="", texture=None)
    with _SPLATS_LOCK:
        SPLATS.clear()
