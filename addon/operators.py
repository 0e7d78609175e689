"""Operators: precompute (off the UI thread, progress bar, Esc cancels) and clear the preview.

Both take the material by name (`material_name`; the panel passes its own), so a script runs
them from any context; without a name they take the context's material (the active object's).
Blender's `poll` cannot see an operator's properties, so it refuses nothing a name could make
valid: `execute` resolves the material and reports what is wrong, naming it."""

from __future__ import annotations

import bpy

from . import edits, jobs, panel, splat_view, viewport, writeback
from .session import JOBS, SESSIONS, objects_with


def _context_material(context):
    obj = getattr(context, "object", None)
    return getattr(context, "material", None) or (obj.active_material if obj is not None else None)


def _resolve(op, context, needs_preview: bool):
    """The operator's material: `op.material_name` looked up in bpy.data.materials, else the
    context's. None, with an error report naming what is missing, when there is none."""
    if op.material_name:
        mat = bpy.data.materials.get(op.material_name)
        if mat is None:
            op.report({"ERROR"}, f"material_name: no material named {op.material_name!r} in this file")
            return None
    else:
        mat = _context_material(context)
        if mat is None:
            op.report({"ERROR"}, "no material: pass material_name, or make an object with a material active")
            return None
    if needs_preview and not mat.translucent.enabled:
        op.report({"ERROR"}, f"material {mat.name!r}: the preview is off (material.translucent.enabled = True)")
        return None
    return mat


def _run_modal(op, context, job) -> set:
    """`job` started off the UI thread with a progress bar; `op.modal` polls it (`_poll`)."""
    op._job = job
    job.start()
    wm = context.window_manager
    wm.progress_begin(0, 100)
    op._timer = wm.event_timer_add(0.1, window=context.window)
    wm.modal_handler_add(op)
    return {"RUNNING_MODAL"}


def _poll(op, context, event, what: str):
    """One modal event for `op._job`: Esc cancels it; on a timer the progress bar and status
    say how far `what` is. None once the job is done (the bar and status cleared), else the
    modal's answer."""
    wm = context.window_manager
    if event.type == "ESC":
        op._job.cancel = True
    if event.type != "TIMER":
        return {"PASS_THROUGH"}
    wm.progress_update(int(100 * op._job.progress))
    context.workspace.status_text_set(f"Translucent: {what} {100 * op._job.progress:.0f} % (Esc cancels)")
    if not op._job.done:
        return {"RUNNING_MODAL"}
    wm.event_timer_remove(op._timer)
    wm.progress_end()
    context.workspace.status_text_set(None)
    for area in context.screen.areas:
        area.tag_redraw()
    return None


class TRANSLUCENT_OT_precompute(bpy.types.Operator):
    """Precompute light transport for the objects using this material (Xu 2007 PRT, or the hierarchy)"""

    bl_idname = "translucent.precompute"
    bl_label = "Precompute"
    bl_options = {"REGISTER", "UNDO"}

    material_name: bpy.props.StringProperty(
        name="Material", description="The material to precompute (empty: the active object's)",
        options={"HIDDEN", "SKIP_SAVE"})

    _timer = None

    def _prepare(self, context, first_preview: bool = False):
        mat = _resolve(self, context, needs_preview=True)
        if mat is None:
            return None
        if mat.name in JOBS:
            # A second press while a job runs does not start a second one.
            what = "an edit is being evaluated" if getattr(JOBS[mat.name], "supersedable", False) else "a precompute is running"
            self.report({"WARNING"}, f"{what} for {mat.name}: press again when it is done")
            return None
        try:
            method, self._method_message = jobs.resolve_method(mat.translucent.method, "precompute")
            job, objects, info, lighting = jobs.start(mat, context.scene, method=method, first_preview=first_preview)
        except ValueError as e:
            self.report({"ERROR"}, str(e))
            return None
        self._mat, self._job, self._objects, self._info, self._lighting = mat.name, job, objects, info, lighting
        return job

    def _finish(self, context):
        JOBS.pop(self._mat, None)
        mat = bpy.data.materials.get(self._mat)
        job = self._job
        if job.error is not None:
            import translucent

            first = SESSIONS.get(self._mat)
            if getattr(self, "_first_shown", False) and first is not None and first.transport is job.first:
                # The first preview stays up; the panel no longer says it is refining.
                first.method_message = "first preview (no walks): the full precompute stopped"

            if isinstance(job.error, translucent.Cancelled):
                self.report({"INFO"}, "precompute cancelled")
                return {"CANCELLED"}
            self.report({"ERROR"}, f"precompute failed: {job.error}")
            return {"CANCELLED"}
        s = edits.finish(mat, job, self._objects, self._info, self._lighting, self._method_message)
        vertices = sum(o.count for o in self._info.objects)
        device = f"; {s.transport.backend_message}" if s.method == "prt" else ""
        self.report({"INFO"}, f"precomputed {vertices} vertices: {panel.summary(s)}{device}")
        return {"FINISHED"}

    def execute(self, context):
        # Scripts and headless Blender: run in this thread (the GIL is released inside).
        job = self._prepare(context)
        if job is None:
            return {"CANCELLED"}
        JOBS[self._mat] = job
        job.run_here()
        return self._finish(context)

    def invoke(self, context, event):
        if bpy.app.background:
            return self.execute(context)
        # Interactive: a first preview within a second while the walks run (Cycles' profile).
        job = self._prepare(context, first_preview=True)
        self._first_shown = False
        if job is None:
            return {"CANCELLED"}
        JOBS[self._mat] = job
        return _run_modal(self, context, job)

    def modal(self, context, event):
        if event.type == "TIMER" and not self._first_shown and self._job.first is not None:
            mat = bpy.data.materials.get(self._mat)
            if mat is not None:
                edits.show_first(mat, self._job, self._objects, self._info, self._lighting)
            self._first_shown = True
        answer = _poll(self, context, event, "precompute")
        return answer if answer is not None else self._finish(context)


class TRANSLUCENT_OT_clear(bpy.types.Operator):
    """Remove the preview attribute from the objects using this material and drop the transport"""

    bl_idname = "translucent.clear"
    bl_label = "Clear Preview"
    bl_options = {"REGISTER", "UNDO"}

    material_name: bpy.props.StringProperty(
        name="Material", description="The material to clear (empty: the active object's)",
        options={"HIDDEN", "SKIP_SAVE"})

    def execute(self, context):
        mat = _resolve(self, context, needs_preview=False)
        if mat is None:
            return {"CANCELLED"}
        SESSIONS.pop(mat.name, None)
        objects = objects_with(mat, context.scene)
        viewport.restore(objects)
        for obj in objects:
            attr = obj.data.color_attributes.get(writeback.ATTRIBUTE)
            if attr is not None:
                obj.data.color_attributes.remove(attr)
        return {"FINISHED"}


class TRANSLUCENT_OT_render_splatting(bpy.types.Operator):
    """Render the previewed materials by image-space splatting (Shah 2009) from a camera into the image
    "Translucent Splatting"."""

    bl_idname = "translucent.render_splatting"
    bl_label = "Render Splatting"
    bl_options = {"REGISTER", "UNDO"}

    camera: bpy.props.StringProperty(name="Camera", description="The camera object (empty: the scene's camera)",
                                     options={"SKIP_SAVE"})
    width: bpy.props.IntProperty(name="Width", description="Pixels across (0: the scene's resolution)", min=0,
                                 max=8192, default=0, options={"SKIP_SAVE"})
    height: bpy.props.IntProperty(name="Height", description="Pixels down (0: the scene's resolution)", min=0,
                                  max=8192, default=0, options={"SKIP_SAVE"})
    filepath: bpy.props.StringProperty(name="File", description="Also save the image here (.exr: linear; "
                                       "otherwise as the scene's output format, colour managed)", subtype="FILE_PATH",
                                       options={"SKIP_SAVE"})
    material_name: bpy.props.StringProperty(name="Material", description="Only this material (empty: every "
                                            "previewed material in the scene)", options={"HIDDEN", "SKIP_SAVE"})

    _timer = None

    def _prepare(self, context):
        scene = context.scene
        cam = bpy.data.objects.get(self.camera) if self.camera else scene.camera
        if cam is None:
            self.report({"ERROR"}, f"camera: no object named {self.camera!r}" if self.camera
                        else "camera: the scene has no camera (pass camera=...)")
            return None
        materials = None
        if self.material_name:
            mat = _resolve(self, context, needs_preview=True)
            if mat is None:
                return None
            materials = [mat]
        size = (self.width, self.height) if self.width and self.height else None
        if (self.width == 0) != (self.height == 0):
            self.report({"ERROR"}, "width, height: give both, or neither (the scene's resolution)")
            return None
        try:
            view = splat_view.camera_view(cam, scene, size)
            return splat_view.prepare(scene, view, materials)
        except ValueError as e:
            self.report({"ERROR"}, str(e))
            return None

    def _finish(self, context, job):
        import translucent

        if job.error is not None:
            if isinstance(job.error, translucent.Cancelled):
                self.report({"INFO"}, "splatting render cancelled")
            else:
                self.report({"ERROR"}, f"splatting render failed: {job.error}")
            return {"CANCELLED"}
        splat_view.store(job.result)
        if self.filepath:
            try:
                splat_view.save(self.filepath, context.scene)
            except RuntimeError as e:
                self.report({"ERROR"}, f"filepath: could not save {self.filepath!r}: {e}")
                return {"CANCELLED"}
        self.report({"INFO"}, splat_view.STATE["message"])
        return {"FINISHED"}

    def execute(self, context):
        job = self._prepare(context)
        if job is None:
            return {"CANCELLED"}
        job.run_here()
        return self._finish(context, job)

    def invoke(self, context, event):
        if bpy.app.background:
            return self.execute(context)
        job = self._prepare(context)
        if job is None:
            return {"CANCELLED"}
        return _run_modal(self, context, job)

    def modal(self, context, event):
        answer = _poll(self, context, event, "splatting")
        return answer if answer is not None else self._finish(context, self._job)


classes = (TRANSLUCENT_OT_precompute, TRANSLUCENT_OT_clear, TRANSLUCENT_OT_render_splatting)
