"""The material panel (Material Properties › Translucent Preview): the settings, and what the
session, its method and the running job say, as lines `status_lines` returns and `draw` shows."""

from __future__ import annotations

import bpy

from . import jobs, principled, splat_view
from .session import JOBS, PREPARING, SESSIONS, Session, state


# The hierarchy's report keys the summary shows, where its report has them (its own keys, not PRT's).
HIERARCHY_SHOWN = (("faces", "faces"), ("clusters", "clusters"), ("links", "links"), ("rays", "rays"))


def _bounce_only(r: dict) -> str:
    """The lights that reach only the other objects, where there are some (they light the
    previewed ones by the bounce alone)."""
    k = r.get("lights_bounce_only", 0)
    return f", {k} lighting them by the other objects' bounce alone" if k else ""


def summary(sess: Session) -> str:
    """What the precompute did and left out, in one line for the status bar and the panel: the
    export's part, then the method's own report as it gives it."""
    # The report the last evaluation on a worker left (the transport may be busy on another).
    r, info = (sess.report if sess.report is not None else sess.transport.report), sess.info
    scene = f"{len(sess.objects)} object(s) ({len(info.skipped_objects)} without the material skipped)"
    if info.without_faces:
        scene += f", {', '.join(info.without_faces)} holding it on no face left out"
    if info.occluders:
        scene += f", {len(info.occluders)} occluder(s)"
    if getattr(info, "unlinked_lights", None):
        scene += f", light(s) lighting none of the exported objects left out (light linking): {', '.join(info.unlinked_lights)}"
    if sess.method == "splat":
        peel = r.get("peel")
        peeled = f", {peel['samples']:,} peeled samples (world, area lights)" if peel else ""
        return (f"{scene}, {len(info.lights)} light(s), {len(info.skipped_lights)} dark skipped, "
                f"world: {info.world}; splatting (Shah 2009), nothing precomputed: {r['splats']:,} splats{peeled}, "
                f"eps {r['eps']:g}, r_max {max(r['r_max']):.4g} units")
    if sess.method == "hierarchy":
        own = ", ".join([f"{r[k]} {label}" for k, label in HIERARCHY_SHOWN if k in r] + [f"{r['seconds']:.2f} s"])
        return (f"{scene}, {len(info.lights)} light(s), {len(info.skipped_lights)} dark skipped, "
                f"world: {info.world}; hierarchy (Mertens 2003): {own}")
    world = "world: no rays (black)" if r["world_skipped"] else f"world: {info.world}"
    w = r["walks"]
    walks = (f"; walks through the mesh: {w['walks_per_vertex']} x {w['walked_vertices']} vertices "
             f"({w['skipped_flat']} flat skipped)" if w else "")
    return (
        f"{scene}, {r['lights_used']} light(s) used, {r['lights_skipped_black'] + len(info.skipped_lights)} dark "
        f"and {r['lights_unreached']} out of reach skipped{_bounce_only(r)}, {world}; {r['samples']} samples, "
        f"{r['coefficients']} coefficients, support radius {r['support_radius']:.4g} units, "
        f"{r['rays']} rays{walks}, {r['seconds']:.2f} s"
    )


def estimate_line(sess: Session) -> str:
    """The last edit's time and the method's own error estimate; "not computed" where the method
    computed none (a number is never made up for it)."""
    if sess.last_error is None:
        err = "est. error: not computed"
    else:
        # Three significant digits: a small estimate (the hierarchy's on a fine mesh) is not
        # rounded to zeros.
        err = f"est. error {', '.join(f'{100 * e:.3g}' for e in sess.last_error)} %"
    return f"Edit {1e3 * sess.last_seconds:.2f} ms, {err}"


def status_lines(mat: bpy.types.Material) -> list[tuple[str, str]]:
    """The panel's lines below the settings, as (text, icon) pairs ("NONE": no icon). Reads what
    the handlers and jobs left on the session: no mesh is evaluated (the follow check does that,
    once the scene is still)."""
    s = mat.translucent
    lines = []
    if s.method in ("AUTO", "HIERARCHY") and not jobs.hierarchy_available():
        lines.append((jobs.HIERARCHY_MISSING, "INFO"))
    st = state(mat)
    if st == "running":
        job = JOBS[mat.name]
        background = getattr(job, "background", False)
        what = getattr(job, "label", "") or ("Refreshing in the background" if background else "Precomputing")
        lines.append((f"{what} {100 * job.progress:.0f} %{'' if background else ' (Esc cancels)'}", "TIME"))
    if st == "none":
        lines.append(("No transport: press Precompute", "INFO"))
    sess = SESSIONS.get(mat.name)
    if st == "stale":
        if sess is not None and sess.changed:
            follows = s.follow_scene and s.enabled
            lines.append((f"Changed: {sess.changed}" + (" (refreshing)" if follows else ""),
                          "TIME" if follows else "ERROR"))
        if not (sess is not None and sess.changed and s.follow_scene):
            lines.append(("Scene, profile or (dipole) IOR changed: transport is stale, precompute again", "ERROR"))
    if sess is None:
        return lines
    if sess.follow_message:
        lines.append((sess.follow_message, "INFO"))
    if sess.layers is not None and sess.layers.message:
        lines.append((sess.layers.message, "INFO" if sess.layers.done else "TIME"))
    if sess.drag is not None and sess.drag.message:
        lines.append((sess.drag.message, "INFO" if sess.drag.ready else "TIME"))
    if sess.method_message:
        lines.append((sess.method_message, "INFO"))
    if sess.edit_message:
        lines.append((sess.edit_message, "TIME" if mat.name in PREPARING else "ERROR"))
    lines += [(part, "NONE") for part in summary(sess).split("; ")]
    # Light and shadow linking: every method follows it; a light lighting none of the exported
    # objects is left out, and said so.
    lines += [(line, "INFO") for line in getattr(sess.info, "linking", [])]
    lines += [(line, "INFO") for line in getattr(sess.info, "emission", [])]
    if getattr(sess.info, "emitters", None):
        lines.append((f"{', '.join(sess.info.emitters)}: emits light in Cycles that the preview does not have "
                      "(its emission could not be read; those faces shadow and bounce only)", "ERROR"))
    if sess.last_eval is not None:
        lines.append((estimate_line(sess), "NONE"))
        # What the method's evaluation left out, and why (its own words).
        lines += [(f"Left out: {k['what']} ({k['why']})", "INFO") for k in sess.last_eval["skipped"]]
        if sess.refresh_advised:
            text = sess.refresh_message if st == "running" or sess.refresh_message.startswith("refresh failed") else (
                "Material outside the basis' range: precompute again")
            lines.append((text, "ERROR"))
        lines += [(why, "ERROR") for why in sess.not_shown]
    return lines


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
        if s.profile == "MULTIPOLE":
            col = layout.column(align=True)
            col.prop(s, "thickness_mm")
            col.prop(s, "top_layer")
            sub = col.column(align=True)
            sub.enabled = s.top_layer != "NONE"
            sub.prop(s, "top_thickness_mm")
        layout.prop(s, "source", expand=True)
        if s.source == "PRINCIPLED":
            p = principled.principled_inputs(mat)
            if p is None:
                layout.label(text="No Principled BSDF: using the coefficients below", icon="ERROR")
            else:
                col = layout.column(align=True)
                for line in principled.input_lines(p):
                    col.label(text=line)
                connected = principled.connected_inputs(mat)
                sess = SESSIONS.get(mat.name)
                if sess is not None and sess.texture_message:
                    means = principled.MEANS.get(mat.name, {})
                    followed = bool(means) or any(x is not None for x in (sess.base_color, sess.subsurface_weight,
                                                                          sess.others))
                    col.label(text=sess.texture_message, icon="TEXTURE" if followed else "ERROR")
                    read = [*means, *(["Base Color"] if sess.base_color is not None else []),
                            *(["Subsurface Weight"] if sess.subsurface_weight is not None else [])]
                    connected = [c for c in connected if not any(c.startswith(f"{name} (") for name in read)]
                if connected:
                    col.label(text=f"Connected, not followed: {', '.join(connected)}; the socket's own value is "
                                   "used everywhere", icon="ERROR")
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
        if mat.name not in JOBS:
            row = layout.row()
            row.enabled = s.enabled
            row.operator("translucent.precompute", icon="RENDER_STILL").material_name = mat.name
        for text, icon in status_lines(mat):
            layout.label(text=text, icon=icon)
        layout.operator("translucent.clear").material_name = mat.name
        # The splatting's camera image (Shah 2009), one for the scene's previewed materials.
        box = layout.box()
        box.label(text="Splatting image (every previewed material)")
        sv = bpy.context.scene.translucent_splat
        row = box.row()
        row.prop(sv, "show_in_viewport")
        row.operator("translucent.render_splatting", icon="RENDER_STILL")
        row = box.row()
        row.prop(sv, "eps")
        row.prop(sv, "max_grid")
        row = box.row()
        row.prop(sv, "max_side")
        row.prop(sv, "backend")
        if splat_view.STATE["message"]:
            box.label(text=splat_view.STATE["message"])


classes = (TRANSLUCENT_PT_material,)
