"""Benchmark of a light's power dragged in the add-on (issue 29, points 2 and 5), the way an
artist meets it: the 10 cm bunny in marble under a point light and a sun, the add-on's
scene following with a UI's worker thread (headless Blender; the timers are run by hand). The
key light is moved (the transport relit), then the sun's power is set three times: each time
from the change to the preview written (export, `Prt.update`, write-back). With the lights'
layers made in the background after the relight (`jobs.LayersPrep`, what the add-on does) and
without (`--no-layers`: the first change relights the sun's layer). Then the key light dragged
(issue 29, point 5): each step from the change to the preview written by the drag's hierarchy
(`drag`: the precompute's walks carried), median of the steps, and PRT's relight once it is still;
the last dragged preview against that relight. `--floor`: a floor under the bunny and a box
beside it, both sending light back (Blender's default grey), as an artist's scene has them.
Prints the machine; timings live here, never in tests.

Run: `make bench` (or .venv/bin/python blender_scripts/bench_drag.py [--profile DIPOLE] [--no-layers]
[--floor]).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import bpy  # noqa: E402

import addon  # noqa: E402
from addon import drag, follow, jobs, session  # noqa: E402
from addon.writeback import ATTRIBUTE  # noqa: E402
from blender_scripts.lib import models  # noqa: E402
from blender_scripts.lib.machine import describe as machine  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--profile", default="CYCLES", choices=["CYCLES", "DIPOLE"])
    ap.add_argument("--no-layers", action="store_true", help="the add-on makes no layer ahead")
    ap.add_argument("--floor", action="store_true", help="a floor under the bunny and a box beside it")
    args = ap.parse_args()
    print(f"machine: {machine()}")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.register()
    p, t = models.load("stanford-bunny.obj", diagonal=0.1)
    mesh = bpy.data.meshes.new("Bunny")
    mesh.from_pydata(p.tolist(), [], t.tolist())
    obj = bpy.data.objects.new("Bunny", mesh)
    bpy.context.scene.collection.objects.link(obj)
    if args.floor:
        low = float(p[:, 2].min())
        bpy.ops.mesh.primitive_plane_add(size=0.5, location=(0.0, 0.0, low))
        bpy.ops.mesh.primitive_cube_add(size=0.03, location=(0.07, -0.05, low + 0.015))
        print(f"a floor under the bunny (z = {low:.3f}) and a box beside it, Blender's default grey")
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
    prep = session.SESSIONS[mat.name].drag
    if prep is None:
        print("key light dragged: no drag hierarchy (the dipole, or no walks): PRT relights at each step")
        return 0
    prep._thread.join()
    print(f"key light dragged: {prep.message}")

    def preview() -> np.ndarray:
        a = mesh.attributes[ATTRIBUTE]
        out = np.empty(len(a.data) * 4, np.float32)
        a.data.foreach_get("color", out)
        return out.reshape(-1, 4)[:, :3].copy()

    steps = []
    for _ in range(5):
        key.location.x -= 0.01
        t0 = time.perf_counter()
        bpy.context.view_layer.update()
        follow.follow_now(dragging={mat.name})
        job = session.JOBS[mat.name]
        assert isinstance(job, drag.DragJob), type(job)
        job._thread.join(timeout=600)
        poll = next(fn for fn in timers if fn.__name__ == "poll")
        timers.remove(poll)
        assert poll() is None
        steps.append(time.perf_counter() - t0)
    dragged = preview()
    print(f"  drag steps: median {statistics.median(steps):.3f} s from the change to the preview written "
          f"({', '.join(f'{x:.3f}' for x in steps)}; {session.SESSIONS[mat.name].follow_message})")
    took = refresh()
    relit = preview()
    rel = np.sqrt(np.mean((dragged - relit) ** 2, axis=0) / np.mean(relit**2, axis=0))
    print(f"  still: PRT relit in {took:.2f} s ({session.SESSIONS[mat.name].follow_message}); the last dragged "
          f"preview {', '.join(f'{100 * x:.2f}' for x in rel)} % from it (RMS over the vertices)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
