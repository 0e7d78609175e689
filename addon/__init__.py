"""Translucent: subsurface-scattering preview for Blender (Cycles' random walk or Jensen's
dipole, PRT after Xu 2007).

Blender-side code only: settings (`properties`), operators, the material panel, scene export
(`export`) and colour write-back (`writeback`). All maths lives in the native `translucent`
module. Enable the preview on a material, press Precompute, then drag the sliders: the
objects' "translucent_preview" colour attribute follows, and Solid viewports show it
(`viewport`) until the preview is turned off. Posing, deforming, scrubbing the timeline or
moving a light refreshes the preview on its own (`session.follow_scene`), in the background.
"""

import bpy

from . import operators, properties, session, viewport


class TRANSLUCENT_PT_material(bpy.types.Panel):
    bl_label = "Translucent Preview"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "material"

    @classmethod
    def poll(cls, context):
        return context.material is not None

    def draw_header(self, context):
        self.layout.prop(context.material.translucent, "enabled", text="")

    def draw(self, context):
        layout = self.layout
        mat = context.material
        s = mat.translucent
        layout.active = s.enabled
        layout.prop(s, "profile")
        layout.prop(s, "source", expand=True)
        if s.source == "PRINCIPLED":
            p = properties.principled_inputs(mat)
            if p is None:
                layout.label(text="No Principled BSDF: using the coefficients below", icon="ERROR")
            else:
                col = layout.column(align=True)
                col.label(text=f"Radius {', '.join(f'{r:.3g}' for r in p.radius)} x Scale {p.scale:.3g}, "
                          f"Anisotropy {p.anisotropy:.2f}, IOR {p.ior:.3g}")
                col.label(text=f"Subsurface Weight {p.subsurface_weight:.2f}, Roughness {p.roughness:.2f}, "
                          f"Metallic {p.metallic:.2f}, Transmission {p.transmission:.2f}")
        else:
            layout.prop(s, "preset")
        col = layout.column()
        col.enabled = s.source == "CUSTOM"
        col.prop(s, "sigma_a")
        col.prop(s, "sigma_s")
        col.prop(s, "g")
        col.prop(s, "eta")
        layout.prop(s, "mm_per_unit")
        row = layout.row()
        row.prop(s, "coefficients")
        row.prop(s, "degree", text="")
        row = layout.row()
        row.prop(s, "backend")
        row.prop(s, "auto_refresh")
        row = layout.row()
        row.prop(s, "method")
        row.prop(s, "follow_scene")
        if s.method != "PRT" and not session.hierarchy_available():
            layout.label(text=session.HIERARCHY_MISSING, icon="INFO")
        # Everything below reads what the handlers and jobs left on the session: a redraw
        # evaluates no mesh (the follow check does, once the scene is still).
        state = session.state(mat)
        if state == "running":
            job = session.JOBS[mat.name]
            what = "Refreshing in the background" if getattr(job, "background", False) else "Precomputing"
            esc = "" if getattr(job, "background", False) else " (Esc cancels)"
            layout.label(text=f"{what} {100 * job.progress:.0f} %{esc}", icon="TIME")
        else:
            layout.operator("translucent.precompute", icon="RENDER_STILL")
        if state == "none":
            layout.label(text="No transport: press Precompute", icon="INFO")
        sess = session.SESSIONS.get(mat.name)
        if state == "stale":
            if sess is not None and sess.changed:
                follows = s.follow_scene and s.enabled
                layout.label(text=f"Changed: {sess.changed}" + (" (refreshing)" if follows else ""),
                             icon="TIME" if follows else "ERROR")
            if not (sess is not None and sess.changed and s.follow_scene):
                layout.label(text="Scene, profile or (dipole) IOR changed: transport is stale, precompute again",
                             icon="ERROR")
        if sess is not None and sess.follow_message:
            layout.label(text=sess.follow_message, icon="INFO")
        if sess is not None and sess.method_message:
            layout.label(text=sess.method_message, icon="INFO")
        if sess is not None and sess.edit_message:
            layout.label(text=sess.edit_message, icon="TIME" if mat.name in session.PREPARING else "ERROR")
        if sess is not None:
            col = layout.column(align=True)
            for part in session.summary(sess).split("; "):
                col.label(text=part)
        if sess is not None and sess.last_error:
            err = ", ".join(f"{100 * e:.2f}" for e in sess.last_error)
            layout.label(text=f"Edit {1e3 * sess.last_seconds:.2f} ms, est. error {err} %")
            if sess.refresh_advised:
                text = sess.refresh_message if state == "running" or sess.refresh_message.startswith("refresh failed") else (
                    "Material outside the basis' range: precompute again")
                layout.label(text=text, icon="ERROR")
            for name in sess.not_shown:
                layout.label(text=f"{name}: mesh changed since the precompute, not shown", icon="ERROR")
        layout.operator("translucent.clear")


@bpy.app.handlers.persistent
def _drop_sessions(*_args):
    """A loaded file starts without transport (it is not saved); the panel asks for a precompute."""
    session.SESSIONS.clear()
    session.JOBS.clear()
    session.PENDING.clear()
    viewport.forget()


classes = (TRANSLUCENT_PT_material,)


def register():
    properties.register()
    for cls in operators.classes + classes:
        bpy.utils.register_class(cls)
    bpy.app.handlers.load_post.append(_drop_sessions)
    bpy.app.handlers.depsgraph_update_post.append(session.follow_principled)
    bpy.app.handlers.depsgraph_update_post.append(session.follow_scene)
    bpy.app.handlers.frame_change_post.append(session.follow_frame)
    if not bpy.app.timers.is_registered(session.follow_view_tick):
        bpy.app.timers.register(session.follow_view_tick, first_interval=session.VIEW_POLL_S, persistent=True)


def unregister():
    for handlers, fn in ((bpy.app.handlers.load_post, _drop_sessions),
                         (bpy.app.handlers.depsgraph_update_post, session.follow_principled),
                         (bpy.app.handlers.depsgraph_update_post, session.follow_scene),
                         (bpy.app.handlers.frame_change_post, session.follow_frame)):
        if fn in handlers:
            handlers.remove(fn)
    if bpy.app.timers.is_registered(session.follow_tick):
        bpy.app.timers.unregister(session.follow_tick)
    if bpy.app.timers.is_registered(session.follow_view_tick):
        bpy.app.timers.unregister(session.follow_view_tick)
    session.PENDING.clear()
    for cls in reversed(operators.classes + classes):
        bpy.utils.unregister_class(cls)
    viewport.restore()
    properties.unregister()
    session.SESSIONS.clear()
