"""Benchmark of a light's power dragged in the add-on (issue 29, points 2 and 5), the way an
artist meets it: the 10 cm bunny in marble under a point light and a sun, the add-on's
scene following with a UI's worker thread (headless Blender; the timers are run by hand). The
key light is moved (the transport relit), then the sun's power is set three times: each time
from the change to the preview written (export, `Prt.update`, write-back). With the lights'
layers made in the background after the relight (`jobs.LayersPrep`, what the add-on does) and
without (`--no-layers`: the first change relights the sun's layer). Prints the machine;
timings live here, never in tests.

Run: `make bench` (or .venv/bin/python blender_scripts/bench_drag.py [--profile DIPOLE] [--no-layers]).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import bpy  # noqa: E402

import addon  # noqa: E402
from addon import follow, jobs, session  # noqa: E402
from blender_scripts.lib import models  # noqa: E402
from blender_scripts.lib.machine import describe as machine  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--profile", default="CYCLES", choices=["CYCLES", "DIPOLE"])
    ap.add_argument("--no-layers", action="store_true", help="the add-on makes no layer ahead")
    args = ap.parse_args()
    print(f"machine: {machine()}")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.register()
    p, t = models.load("stanford-bunny.obj", diagonal=0.1)
    mesh = bpy.data.meshes.new("Bunny")
    mesh.from_pydata(p.tolist(), [], t.tolist())
    obj = bpy.data.objects.new("Bunny", mesh)
    bpy.context.scene.collection.objects.link(obj)
    mat = bpy.data.materials.new("Marble")
    obj.data.materials.append(mat)
    key = bpy.data.objects.new("Key", bpy.data.lights.new("Key", "POINT"))
    key.data.energy, key.location = 5.0, (0.1, -0.15, 0.15)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy, sun.rotation_euler = 2.0, (0.6, 0.3, 0.0)
    for light in (key, sun):
        bpy.context.scene.collection.objects.link(light)
    s = mat.translucent
    s.enabled, s.preset, s.method, s.profile = True, "MARBLE", "PRT", args.profile
    t0 = time.perf_counter()
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    print(f"precompute: {time.perf_counter() - t0:.1f} s ({len(p)} vertices, {args.profile.lower()} profile)")

    # From here on, the path Blender with a window takes: jobs on worker threads, polled.
    timers = []
    jobs.headless = lambda: False
    if args.no_layers:
        jobs.prepare_layers = lambda sess, scene: None
    bpy.app.timers.register = lambda fn, first_interval=0.0, persistent=False: timers.append(fn)
    bpy.app.timers.is_registered = lambda fn: fn in timers

    def refresh() -> float:
        t0 = time.perf_counter()
        bpy.context.view_layer.update()
        follow.follow_now()
        session.JOBS[mat.name]._thread.join(timeout=600)
        poll = next(fn for fn in timers if fn.__name__ == "poll")
        timers.remove(poll)
        assert poll() is None
        return time.perf_counter() - t0

    key.location.x += 0.01
    print(f"key light moved: {refresh():.2f} s ({session.SESSIONS[mat.name].follow_message})")
    layers = session.SESSIONS[mat.name].layers
    if layers is not None:
        t0 = time.perf_counter()
        layers._thread.join()
        print(f"  then {layers.message} (waited {time.perf_counter() - t0:.2f} s)")
    for energy in (2.5, 3.0, 3.5):
        sun.data.energy = energy
        took = refresh()
        print(f"sun's power {energy}: {took:.3f} s from the change to the preview written "
              f"({session.SESSIONS[mat.name].follow_message})")
        if session.SESSIONS[mat.name].layers is not None:
            session.SESSIONS[mat.name].layers._thread.join()
    return 0


if __name__ == "__main__":
    sys.exit(main())
