"""Translucent: subsurface-scattering preview for Blender (Cycles' random walk or Jensen's
dipole, PRT after Xu 2007, or the hierarchy after Mertens 2003).

Blender-side code only; all maths lives in the native `translucent` module. The modules:
`properties` (the settings, stored on the material), `principled` (the Principled BSDF read
and the medium shown in the coefficient fields), `operators` (precompute, clear), `panel` (the
material panel), `session` (each previewed material's transport), `jobs` (the transport built
on a worker thread, by PRT or the hierarchy), `edits` (an edit refitted, evaluated and written
back), `follow` (following the scene and the view), `export` (the scene for the native module),
`writeback` (the colour attribute), `viewport` (the Solid viewports while the preview is on)
and `splat_view` (the splatting's camera image, Shah 2009, drawn over the viewports).

Enable the preview on a material, press Precompute, then drag the sliders: the objects'
"translucent_preview" colour attribute follows, and Solid viewports show it until the preview
is turned off. Posing, deforming, scrubbing the timeline or moving a light refreshes the
preview on its own (`follow.follow_scene`), in the background.
"""

import bpy

from . import edits, follow, operators, panel, properties, session, splat_view, viewport


@bpy.app.handlers.persistent
def _drop_sessions(*_args):
    """A loaded file starts without transport (it is not saved); the panel asks for a precompute."""
    session.forget()
    follow.PENDING.clear()
    viewport.forget()
    splat_view.forget()


HANDLERS = ((bpy.app.handlers.load_post, _drop_sessions),
            (bpy.app.handlers.depsgraph_update_post, edits.follow_principled),
            (bpy.app.handlers.depsgraph_update_post, follow.follow_scene),
            (bpy.app.handlers.frame_change_post, follow.follow_frame),
            (bpy.app.handlers.depsgraph_update_post, splat_view.follow_depsgraph),
            (bpy.app.handlers.frame_change_post, splat_view.follow_depsgraph))


def register():
    properties.register()
    for cls in operators.classes + panel.classes:
        bpy.utils.register_class(cls)
    for handlers, fn in HANDLERS:
        handlers.append(fn)
    splat_view.register()
    if not bpy.app.timers.is_registered(follow.follow_view_tick):
        bpy.app.timers.register(follow.follow_view_tick, first_interval=follow.VIEW_POLL_S, persistent=True)


def unregister():
    for handlers, fn in HANDLERS:
        if fn in handlers:
            handlers.remove(fn)
    for timer in (follow.follow_tick, follow.follow_view_tick):
        if bpy.app.timers.is_registered(timer):
            bpy.app.timers.unregister(timer)
    follow.PENDING.clear()
    for cls in reversed(operators.classes + panel.classes):
        bpy.utils.unregister_class(cls)
    viewport.restore()
    splat_view.unregister()
    properties.unregister()
    session.SESSIONS.clear()
