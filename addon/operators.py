"""Operators: precompute (off the UI thread, progress bar, Esc cancels) and stop previewing."""

from __future__ import annotations

import bpy

from . import session, viewport, writeback


def _material(context):
    return getattr(context, "material", None) or (context.object.active_material if context.object else None)


class TRANSLUCENT_OT_precompute(bpy.types.Operator):
    """Precompute light transport for the objects using this material (Xu 2007 PRT)"""

    bl_idname = "translucent.precompute"
    bl_label = "Precompute"
    bl_options = {"REGISTER", "UNDO"}

    material_name: bpy.props.StringProperty(options={"HIDDEN", "SKIP_SAVE"})

    _timer = None

    def _target(self, context):
        if self.material_name:
            return bpy.data.materials.get(self.material_name)
        return _material(context)

    @classmethod
    def poll(cls, context):
        m = _material(context)
        # A second press while a job runs does not start a second one.
        return m is not None and m.translucent.enabled and m.name not in session.JOBS

    def _prepare(self, context):
        mat = self._target(context)
        if mat is None:
            self.report({"ERROR"}, "no material")
            return None
        if mat.name in session.JOBS:
            self.report({"WARNING"}, f"a precompute for {mat.name} is already running")
            return None
        try:
            method, self._method_message = session.resolve_method(mat.translucent.method, "precompute")
            job, objects, info, lighting = session.start(mat, context.scene, method=method)
        except ValueError as e:
            self.report({"ERROR"}, str(e))
            return None
        self._mat, self._job, self._objects, self._info, self._lighting = mat.name, job, objects, info, lighting
        return job

    def _finish(self, context):
        session.JOBS.pop(self._mat, None)
        mat = bpy.data.materials.get(self._mat)
        job = self._job
        if job.error is not None:
            import translucent

            if isinstance(job.error, translucent.Cancelled):
                self.report({"INFO"}, "precompute cancelled")
                return {"CANCELLED"}
            self.report({"ERROR"}, f"precompute failed: {job.error}")
            return {"CANCELLED"}
        s = session.finish(mat, job, self._objects, self._info, self._lighting, self._method_message)
        vertices = sum(o.count for o in self._info.objects)
        self.report({"INFO"}, f"precomputed {vertices} vertices: {session.summary(s)}; {s.prt.backend_message}")
        return {"FINISHED"}

    def execute(self, context):
        # Scripts and headless Blender: run in this thread (the GIL is released inside).
        job = self._prepare(context)
        if job is None:
            return {"CANCELLED"}
        session.JOBS[self._mat] = job
        job.run_here()
        return self._finish(context)

    def invoke(self, context, event):
        if bpy.app.background:
            return self.execute(context)
        job = self._prepare(context)
        if job is None:
            return {"CANCELLED"}
        session.JOBS[self._mat] = job
        job.start()
        wm = context.window_manager
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        wm = context.window_manager
        if event.type == "ESC":
            self._job.cancel = True
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        wm.progress_update(int(100 * self._job.progress))
        context.workspace.status_text_set(f"Translucent: precompute {100 * self._job.progress:.0f} % (Esc cancels)")
        if not self._job.done:
            return {"RUNNING_MODAL"}
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        context.workspace.status_text_set(None)
        for area in context.screen.areas:
            area.tag_redraw()
        return self._finish(context)


class TRANSLUCENT_OT_clear(bpy.types.Operator):
    """Remove the preview attribute from the objects using this material and drop the transport"""

    bl_idname = "translucent.clear"
    bl_label = "Clear Preview"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return _material(context) is not None

    def execute(self, context):
        mat = _material(context)
        session.SESSIONS.pop(mat.name, None)
        objects = session.objects_with(mat, context.scene)
        viewport.restore(objects)
        for obj in objects:
            attr = obj.data.color_attributes.get(writeback.ATTRIBUTE)
            if attr is not None:
                obj.data.color_attributes.remove(attr)
        return {"FINISHED"}


classes = (TRANSLUCENT_OT_precompute, TRANSLUCENT_OT_clear)
