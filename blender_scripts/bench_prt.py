"""Benchmark of the PRT method (issue 3, point 9). Prints medians of several runs and the
machine; timings live here, never in tests.

0. Cycles' random-walk table: the build of one table (Monte Carlo of the walk), g = 0 and 0.8.
1. Precompute: the Stanford bunny scaled to 10 cm, marble, 32 coefficients, Cycles' profile and
   the dipole (budget: 20 s on the 2-core CI machine); the first preview (budget 1 s), the
   relight (`update(lights=...)`) and a pose (`update(positions=...)`, PRT and the hierarchy
   with walks; budget 1 s).
2. One edit (coefficient fit + dot product, 3 channels) on a >= 120k-vertex mesh (the bunny
   subdivided once; budget: 5 ms on the CPU), Cycles' profile; on the same mesh an edit with a
   Base Color per vertex, without and with the walks and the own light (budget 10 ms), and a
   uniform material beside another material's faces (budget 5 ms).
3. Single scattering (Xu 2007 eqs. 12-15, the dipole): the MS + SS precompute of that mesh and
   one MS + SS edit (radiance toward an eye: L_d + L^(1), exact HG), beside MS alone.
4. The bunny on a floor: the dipole's precompute with the floor a shadow only and sending light
   back (one diffuse bounce).

Run: `make bench` (or .venv/bin/python blender_scripts/bench_prt.py [--runs N]).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from blender_scripts.lib import models  # noqa: E402
from blender_scripts.lib.machine import describe as machine  # noqa: E402

import translucent  # noqa: E402


# Samples on the subdivided bunny (139,122 vertices, 277,804 triangles): about two a triangle.
BIG_SAMPLES = 600_000


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=3, help="precompute runs (median)")
    ap.add_argument("--edits", type=int, default=30, help="edit runs (median)")
    args = ap.parse_args()
    print(f"machine: {machine()}")
    print(f"translucent {translucent.__version__}")

    # Tables from scratch: the cache in memory only, a new Roughness per run (a new table).
    cache = translucent.table_cache()
    translucent.set_table_cache(None)
    for g in (0.0, 0.8):
        builds = []
        for k in range(args.runs):
            m = translucent.Material((0.1, 0.2, 0.3), 50.0, g=g, eta=1.4).with_layers(roughness=0.15 + 0.1 * k)
            builds.append(translucent.prepare_profile(m))
        print(f"walk table, g {g}: build median {statistics.median(builds):.2f} s over {args.runs} tables "
              "(100 albedos x 96 radii; kept on disk after the first build)")
    translucent.set_table_cache(cache)

    marble = translucent.Material.preset("marble", mm_per_unit=1000.0)
    p, t = models.load("stanford-bunny.obj", diagonal=0.1)
    scene = models.standard_scene(p, t)
    translucent.prepare_profile(marble)
    kept = {}
    for profile in ("cycles", "dipole"):
        times, reports = [], []
        for _ in range(args.runs):
            t0 = time.perf_counter()
            # Multiple scattering alone here; single scattering has its own lines below.
            prt = translucent.Prt(scene, marble, coefficients=32, profile=profile, single_scattering=False)
            times.append(time.perf_counter() - t0)
            reports.append(prt.report)
        r = reports[-1]
        w = r["walks"]
        wi = r.get("walks_indirect")
        walks = (f", walks through the mesh {w['seconds']:.2f} s: {w['walks_per_vertex']} walks per vertex x "
                 f"{w['walked_vertices']} vertices ({w['skipped_flat']} flat, skipped), {w['rays'] / 1e6:.1f} M rays, "
                 f"their noise {100 * max(w['noise']):.1f} % of B" if w else "")
        walks += (f"; for the object's own light {wi['seconds']:.2f} s: {wi['walks_per_vertex']} walks per vertex x "
                  f"{wi['walked_vertices']} vertices, {wi['rays'] / 1e6:.1f} M rays" if wi else "")
        print(
            f"\nprecompute, bunny 10 cm ({scene.vertex_count} vertices, {r['samples']} samples), marble, "
            f"{profile} profile, 32 coefficients: median {statistics.median(times):.2f} s over {args.runs} runs "
            f"(the first {times[0]:.2f} s) "
            f"(irradiance {r['seconds_irradiance']:.2f} s, tree {r['seconds_tree']:.2f} s, "
            f"transport {r['seconds_transport']:.2f} s, the object's own light {r['seconds_interreflection']:.2f} s "
            f"for {r['interreflection_rays']} rays{walks}) [budget 20 s]"
        )
        kept[profile] = (prt, statistics.median(times))
    first_preview(scene, marble, kept["cycles"][0], args)
    relight(p, t, marble, kept, args)
    power_drag(p, t, marble, kept, args)
    pose(p, t, marble, kept["cycles"][0], args)
    floor_bounce(p, t, marble, args)

    # Growth: the same surface with 4x the vertices and 4x the samples. Brute force (Xu 2007
    # §6.1) would take 16x; the clustered far field should take a little over 4x.
    p2, t2 = models.subdivide(p, t)
    big = models.standard_scene(p2, t2)
    grow = []
    for scene_k, samples in ((scene, 250_000), (big, 1_000_000)):
        ts = []
        for _ in range(args.runs):
            t0 = time.perf_counter()
            # The transport alone: the object's own light and the walks are ray casting, linear in
            # vertices (the walks have a fixed ray budget).
            translucent.Prt(scene_k, marble, coefficients=32, samples=samples, interreflection=False, walks=0)
            ts.append(time.perf_counter() - t0)
        grow.append(statistics.median(ts))
    print(
        f"growth: {scene.vertex_count} vertices / 250k samples {grow[0]:.2f} s -> "
        f"{big.vertex_count} vertices / 1M samples {grow[1]:.2f} s: x{grow[1] / grow[0]:.1f} "
        f"for x4 work (brute force would be x16)"
    )
    # The edit's cost depends on the vertices and coefficients alone; 600k samples is about two
    # per triangle (each of the 277,804 triangles takes one at least).
    prt = translucent.Prt(big, marble, coefficients=32, samples=BIG_SAMPLES, backend="cpu")
    skin = translucent.Material.preset("skin1", mm_per_unit=1000.0)
    core, wall = [], []
    for k in range(args.edits):
        m = marble if k % 2 else skin
        t0 = time.perf_counter()
        b = prt.radiosity(m)
        wall.append(time.perf_counter() - t0)
        core.append(prt.last_eval["seconds"])
    assert b.shape == (big.vertex_count, 3)
    last = prt.last_eval
    print(
        f"edit, {big.vertex_count} vertices, 32 coefficients, 3 channels "
        f"({prt.report['stored_channels']} stored, {prt.report['transport_bytes'] / 1e6:.1f} MB): "
        f"median {1e3 * statistics.median(core):.2f} ms in the core "
        f"(fit {1e3 * last['fit_seconds']:.3f} ms, dot {1e3 * last['dot_seconds']:.2f} ms), "
        f"{1e3 * statistics.median(wall):.2f} ms from Python with the numpy copy, "
        f"over {args.edits} edits [budget 5 ms]"
    )
    textured_edits(big, p2, args.edits)
    # Slider to viewport on the CPU path: fit + dot + writing the add-on's colour attribute.
    try:
        import bpy

        from addon import writeback

        mesh = bpy.data.meshes.new("bench")
        mesh.vertices.add(big.vertex_count)
        mesh.vertices.foreach_set("co", p2.ravel())
        totals, writes = [], []
        for k in range(args.edits):
            t0 = time.perf_counter()
            colors = prt.radiance(marble if k % 2 else skin)
            t1 = time.perf_counter()
            writeback.write_colors(mesh, colors)
            t2 = time.perf_counter()
            totals.append(t2 - t0)
            writes.append(t2 - t1)
        print(
            f"slider to viewport, CPU, {big.vertex_count} vertices: median {1e3 * statistics.median(totals):.2f} ms "
            f"(attribute write {1e3 * statistics.median(writes):.2f} ms) [budget 16 ms]"
        )
    except ImportError:
        print("slider to viewport: skipped (bpy not installed)")

    single_scattering(big, p2, marble, skin, args)

    # The same edits through wgpu: a real GPU where there is one, else Mesa's lavapipe.
    try:
        where = prt.set_backend("gpu")
    except RuntimeError as e:
        print(f"edit on the GPU: skipped ({e})")
        return 0
    gpu_edits(f"edit on {where}", lambda k: prt.radiosity(marble if k % 2 else skin), prt, args.edits)
    return 0


def first_preview(scene, marble, full, args) -> None:
    """Issue 29: the time to the first preview the add-on shows while the walks run
    (`Prt(first_preview=True)`: no walks, at most 150,000 samples, the own light on 16 rays a
    vertex), and how far it is from the full precompute's preview."""
    times = []
    for _ in range(args.runs):
        t0 = time.perf_counter()
        prt = translucent.Prt(scene, marble, first_preview=True)
        times.append(time.perf_counter() - t0)
    rms = translucent.relative_error(prt.radiance(marble), full.radiance(marble), scene.vertex_areas)["rms"]
    print(
        f"first preview, bunny 10 cm, marble: median {statistics.median(times):.2f} s over {args.runs} runs "
        f"(transport {prt.report['seconds_transport']:.2f} s, {prt.report['samples']} samples) [budget 1 s]; "
        f"{', '.join(f'{100 * x:.1f}' for x in rms)} % from the full preview (what the walks add)"
    )


def moved_scene(positions, triangles, turn: float, across: float, power: float = 1.0,
                sun: float = 2.0) -> translucent.Scene:
    """The benchmark lighting with the sun turned by `turn` radians about the vertical and the
    point light moved by `across` diagonals along x, its power times `power`; the sun's
    irradiance `sun` [W/m^2]."""
    scene = translucent.Scene(positions, triangles)
    diag = float(np.linalg.norm(positions.max(axis=0) - positions.min(axis=0)))
    scene.add_point_light(((0.6 + across) * diag, -1.0 * diag, 1.2 * diag), power=power * 110.0 * diag**2)
    c, s = np.cos(turn), np.sin(turn)
    scene.add_sun(direction=(0.5 * c - 0.6 * s, 0.5 * s + 0.6 * c, -0.62), irradiance=sun)
    return scene


def relight(positions, triangles, marble, kept, args) -> None:
    """`Prt.update(lights=...)`: the sun turned by 90 degrees and the point light moved across,
    then back; median over the runs, against a fresh precompute under the moved lights."""
    moved = moved_scene(positions, triangles, np.pi / 2, -1.2)
    back = moved_scene(positions, triangles, 0.0, 0.0)
    for profile, (prt, precompute_s) in kept.items():
        times, reports = [], []
        for k in range(args.runs):
            r = prt.update(lights=moved if k % 2 == 0 else back)
            times.append(r["seconds"])
            reports.append(r)
        if args.runs % 2 == 0:
            prt.update(lights=moved)
        r = reports[0]
        fresh = translucent.Prt(moved, marble, coefficients=32, profile=profile, single_scattering=False)
        between = translucent.relative_error(prt.radiance(marble), fresh.radiance(marble), moved.vertex_areas)
        est = [100 * x for x in prt.last_eval["error_estimate"]]
        fresh_est = [100 * x for x in fresh.last_eval["error_estimate"]]
        print(
            f"update(lights=...), bunny, marble, {profile}: sun turned 90 degrees and the point light moved across: "
            f"median {statistics.median(times):.2f} s over {args.runs} updates (precompute {precompute_s:.2f} s: "
            f"x{precompute_s / statistics.median(times):.1f}) (irradiance {r['seconds_irradiance']:.2f} s for "
            f"{r['rays'] / 1e6:.1f} M rays, transport {r['seconds_transport']:.2f} s, walks' term "
            f"{r['seconds_walks']:.3f} s with {r['walks_traced']} walks traced, the object's own light "
            f"{r['seconds_own_light']:.2f} s for {r['own_light_rays'] / 1e6:.1f} M rays); kept for it: "
            f"{(prt.report['walks'] or {}).get('relight_bytes', 0) / 1e6:.1f} MB; "
            f"against a fresh precompute: rel. RMS {', '.join(f'{100 * x:.2f}' for x in between['rms'])} % "
            f"(estimates: updated {', '.join(f'{x:.2f}' for x in est)} %, fresh "
            f"{', '.join(f'{x:.2f}' for x in fresh_est)} %)"
        )
        if profile == "cycles":
            dragged_light(prt, fresh, moved, back, marble, args)


def dragged_light(prt, fresh, moved, back, marble, args) -> None:
    """The add-on's light drag: a hierarchy carrying the precompute's walks
    (`Hierarchy(walks_from=prt)`, no walk traced, built under the moved lights) moved back and
    forth and evaluated, as each drag step does; against the same fresh precompute."""
    t0 = time.perf_counter()
    h = translucent.Hierarchy(moved, marble, mode="render", world_shadows=True, walks_from=prt)
    built = time.perf_counter() - t0
    times = []
    for k in range(2 * args.runs):  # back, moved, ...: the last under the moved lights
        t0 = time.perf_counter()
        h.update(lights=back if k % 2 == 0 else moved)
        dragged = h.radiance(marble)
        times.append(time.perf_counter() - t0)
    between = translucent.relative_error(dragged, fresh.radiance(marble), moved.vertex_areas)["rms"]
    terms = h.report["terms"]
    print(
        f"  the light drag's hierarchy (walks_from=prt, no walk traced): up in {built:.2f} s; the same moves "
        f"median {statistics.median(times):.3f} s over {len(times)} updates with evaluation (the terms "
        f"{terms['seconds']:.3f} s), {', '.join(f'{100 * x:.2f}' for x in between)} % from the fresh "
        f"precompute [budget 100 ms]"
    )


def power_drag(positions, triangles, marble, kept, args) -> None:
    """The point light's power dragged, the sun as it was (one source's emission alone,
    `light_layer`): the first update relights the transport under that light alone (its
    layer), the next ones add it scaled; median of the later ones, and the last against a
    fresh precompute under it."""
    powers = [1.0 + 0.25 * (k + 1) for k in range(max(args.runs, 2) + 1)]
    for profile, (prt, _) in kept.items():
        prt.update(lights=moved_scene(positions, triangles, 0.0, 0.0))
        reports, walls = [], []
        for w in powers:
            lit = moved_scene(positions, triangles, 0.0, 0.0, power=w)
            t0 = time.perf_counter()
            reports.append(prt.update(lights=lit))
            walls.append(time.perf_counter() - t0)
        first, later = reports[0], reports[1:]
        last = moved_scene(positions, triangles, 0.0, 0.0, power=powers[-1])
        fresh = translucent.Prt(last, marble, coefficients=32, profile=profile, single_scattering=False)
        between = translucent.relative_error(prt.radiance(marble), fresh.radiance(marble), last.vertex_areas)
        r = later[len(later) // 2]
        print(
            f"update(lights=...), bunny, marble, {profile}: the point light's power alone dragged (x1.25 to "
            f"x{powers[-1]:.2f}, the sun unchanged): the first update {first['seconds']:.2f} s (its layer relit in "
            f"{first['seconds_layer']:.2f} s), then median {statistics.median(x['seconds'] for x in later):.3f} s over "
            f"{len(later)} ({statistics.median(walls[1:]):.3f} s the whole call from Python; rays {r['rays']}, transport {r['seconds_transport']:.3f} s, walks' term "
            f"{r['seconds_walks']:.3f} s, the object's own light {r['seconds_own_light']:.3f} s, "
            f"from the layer: {all(x['from_layer'] for x in reports)}; the layer kept: {r['layer_bytes'] / 1e6:.1f} MB); against a fresh precompute: "
            f"rel. RMS {', '.join(f'{100 * x:.2f}' for x in between['rms'])} %"
        )
        # Prepared ahead, as the add-on does in the background after a precompute: the sun's
        # layer relit now (the point light's is kept), so the sun's first change adds it.
        prep = prt.prepare_layers(lights=last)
        times, walls = [], []
        for sun in (2.5, 3.0, 3.5)[: max(args.runs, 2)]:
            t0 = time.perf_counter()
            u = prt.update(lights=moved_scene(positions, triangles, 0.0, 0.0, power=powers[-1], sun=sun))
            walls.append(time.perf_counter() - t0)
            times.append(u["seconds"])
            assert u["from_layer"] and u["seconds_layer"] == 0.0, u
        print(
            f"  prepare_layers ahead ({profile}): {prep['built']} layer(s) relit in {prep['seconds']:.2f} s "
            f"({prep['kept']} kept, {prep['layer_bytes'] / 1e6:.1f} MB in all); then the sun's power changed: the first "
            f"update {times[0]:.3f} s ({walls[0]:.3f} s the whole call from Python), every one from its layer"
        )


def bent(positions: np.ndarray, angle: float) -> np.ndarray:
    """The bunny's upper part turned by `angle` about a horizontal axis through its middle, the
    turn blended in over a fifth of its height (a hinge, as a skinned joint bends)."""
    z = positions[:, 2]
    lo, hi = np.quantile(z, 0.5), np.quantile(z, 0.7)
    x = np.clip((z - lo) / (hi - lo), 0.0, 1.0)
    a = angle * x * x * (3.0 - 2.0 * x)
    y, zc = positions[:, 1], z - lo
    out = positions.copy()
    out[:, 1] = np.cos(a) * y - np.sin(a) * zc
    out[:, 2] = np.sin(a) * y + np.cos(a) * zc + lo
    return out.astype(np.float32)


def pose(positions, triangles, marble, precomputed, args) -> None:
    """Issue 29: a pose (the bunny's upper part bent 30 degrees at a hinge) carried by PRT
    (`update(positions=...)`: transport on the pose at a first preview's samples, the walks and
    own light carried) and by the hierarchy with walks, median over the runs; each against a
    fresh precompute on the posed mesh."""
    posed = bent(positions, np.radians(30.0))
    posed_scene = models.standard_scene(posed, triangles)
    prt, times = precomputed, []
    for k in range(args.runs):
        # Posed and back in turn (the way back carries the carried walks again: the same work).
        t0 = time.perf_counter()
        out = prt.update(positions=posed if k % 2 == 0 else positions)
        times.append(time.perf_counter() - t0)
        r = out if k == 0 else r
    if args.runs % 2 == 0:
        prt.update(positions=posed)
    fresh = translucent.Prt(posed_scene, marble, coefficients=32, single_scattering=False)
    area = posed_scene.vertex_areas
    between = translucent.relative_error(prt.radiance(marble), fresh.radiance(marble), area)
    # For scale: the walks' share here, and the carried preview with its walks left out (a bend
    # through the body within marble's centimetre walks changes what they find: docs/walks.md).
    full = fresh.radiosity(marble)
    share = translucent.relative_error(fresh.radiosity(marble, walks=False), full, area)
    bare = translucent.relative_error(prt.radiosity(marble, walks=False), full, area)
    print(
        f"update(positions=...), bunny, marble, cycles: upper part bent 30 degrees: median "
        f"{statistics.median(times):.2f} s over {args.runs} poses [budget 1 s] (irradiance "
        f"{r['seconds_irradiance']:.2f} s, transport {r['seconds_transport']:.2f} s, walks carried "
        f"{r['seconds_walks']:.2f} s with {r['walks_traced']} traced, own light {r['seconds_own_light']:.2f} s); "
        f"against a fresh precompute on the pose: {', '.join(f'{100 * x:.2f}' for x in between['rms'])} % "
        f"(with the carried walks left out {', '.join(f'{100 * x:.2f}' for x in bare['rms'])} %; the fresh "
        f"precompute's own walks are {', '.join(f'{100 * x:.2f}' for x in share['rms'])} % of it)"
    )
    h = translucent.Hierarchy(models.standard_scene(positions, triangles), marble, mode="render", walks=True)
    times = []
    for k in range(args.runs):
        t0 = time.perf_counter()
        h.update(positions=posed if k % 2 == 0 else positions)
        h.radiance(marble)
        times.append(time.perf_counter() - t0)
    if args.runs % 2 == 0:
        h.update(positions=posed)
    between = translucent.relative_error(h.radiance(marble), fresh.radiance(marble), posed_scene.vertex_areas)
    print(
        f"Hierarchy(walks=True).update(positions=...), the same pose and back: median "
        f"{statistics.median(times):.2f} s over {args.runs} [budget 1 s]; against the fresh precompute: "
        f"{', '.join(f'{100 * x:.2f}' for x in between['rms'])} %"
    )


def textured_edits(scene, positions, edits) -> None:
    """Issue 30: an edit with the Base Color per vertex (a texture read by Cycles in the add-on;
    here a pattern over the whole [0.05, 0.95] range in every channel), the Subsurface Scale
    slider moved between edits: the table of media fitted again and the interpolated dot
    product, on the CPU. The transport is chosen for the pattern's mean, brightest and darkest
    Base Colour (as the add-on does); no walks, no own light (`BIG_SAMPLES` samples); then the
    same with the walks' term and the own light, as the add-on has it with Cycles' profile."""
    x = positions[:, 0] / np.ptp(positions[:, 0])
    colours = np.stack([0.5 + 0.45 * np.sin(40 * x), 0.5 + 0.45 * np.cos(31 * x), 0.5 + 0.45 * np.sin(23 * x + 1)], 1)
    reps = [translucent.Material.from_principled(tuple(c), (1.0, 0.35, 0.2), 0.002)
            for c in (colours.mean(0), colours.max(0), colours.min(0))]
    prt = translucent.Prt(scene, reps, coefficients=32, samples=BIG_SAMPLES, backend="cpu", walks=0,
                          interreflection=False, single_scattering=False)
    core, fits = [], []
    for k in range(edits):
        m = translucent.Material.from_principled(0.8, (1.0, 0.35, 0.2), 0.002 + 0.0002 * (k % 2))
        prt.radiance(m, base_color=colours)
        core.append(prt.last_eval["seconds"])
        fits.append(prt.last_eval["fit_seconds"])
    estimate = max(prt.last_eval["error_estimate"])
    uniform = []
    for k in range(edits):
        m = translucent.Material.from_principled(0.8, (1.0, 0.35, 0.2), 0.002 + 0.0002 * (k % 2))
        prt.radiance(m)
        uniform.append(prt.last_eval["seconds"])
    print(
        f"edit with a Base Color per vertex, {len(colours)} vertices, colours over [0.05, 0.95]: median "
        f"{1e3 * statistics.median(core):.2f} ms in the core (the media's table {1e3 * statistics.median(fits):.2f} ms), "
        f"the same material uniform {1e3 * statistics.median(uniform):.2f} ms, over {edits} edits, estimate "
        f"{100 * estimate:.2f} % [budget 10 ms]"
    )
    # As the add-on has it with Cycles' profile: the walks' term read at each vertex's medium (the
    # pattern's media walked beside the mean's, walks/media.rs) and the object's own light.
    prt = translucent.Prt(scene, reps, coefficients=32, samples=BIG_SAMPLES, backend="cpu", single_scattering=False)
    walked = []
    for k in range(edits):
        m = translucent.Material.from_principled(0.8, (1.0, 0.35, 0.2), 0.002 + 0.0002 * (k % 2))
        prt.radiance(m, base_color=colours)
        walked.append(prt.last_eval["seconds"])
    print(
        f"the same with the walks' term ({prt.report['walks']['media']} media walked) and the own light: median "
        f"{1e3 * statistics.median(walked):.2f} ms in the core over {edits} edits [budget 10 ms]"
    )
    other_materials_edits(scene, positions, edits)


def other_materials_edits(scene, positions, edits) -> None:
    """Issue 30: a uniform material whose object has faces of another material that scatter as
    their own colour (the add-on passes their albedo apart, `Prt.radiance(others=...)`, NaN rows
    for the previewed vertices): a tenth of the vertices here, the walks (for the previewed
    medium) and the own light on. Scale edits and Base Color edits; beside them the Base Color
    edit with both colours per vertex (`base_color=`, what the add-on passed before) and every
    face the material."""
    x = positions[:, 0] / np.ptp(positions[:, 0])
    other = x > np.quantile(x, 0.9)
    shown = np.array([0.8, 0.45, 0.35], np.float32)
    reps = [translucent.Material.from_principled(tuple(shown), (1.0, 0.35, 0.2), 0.002),
            translucent.Material.from_principled((0.9, 0.9, 0.9), (1.0, 0.35, 0.2), 0.002)]
    prt = translucent.Prt(scene, reps, coefficients=32, samples=BIG_SAMPLES, backend="cpu",
                          single_scattering=False, walk_media=1)
    # Each slider dragged on its own, as an artist does.
    times = {"scale": [], "colour": [], "per_vertex": [], "uniform": []}
    scale = [translucent.Material.from_principled(tuple(shown), (1.0, 0.35, 0.2), 0.002 + 0.0002 * (k % 2))
             for k in range(edits)]
    colour = [translucent.Material.from_principled(tuple(shown * (1.0 + 0.05 * (k % 2))), (1.0, 0.35, 0.2), 0.002)
              for k in range(edits)]
    others = np.where(other[:, None], np.full((len(x), 3), 0.9, np.float32), np.float32(np.nan)).astype(np.float32)
    for m in scale:
        prt.radiance(m, others=others)
        times["scale"].append(prt.last_eval["seconds"])
    for m in colour:
        prt.radiance(m, others=others)
        times["colour"].append(prt.last_eval["seconds"])
    for m in colour:
        merged = np.where(other[:, None], np.float32(0.9), np.float32(m.base_color)).astype(np.float32)
        prt.radiance(m, base_color=merged)
        times["per_vertex"].append(prt.last_eval["seconds"])
    for m in scale:
        prt.radiance(m)
        times["uniform"].append(prt.last_eval["seconds"])
    med = {k: 1e3 * statistics.median(v) for k, v in times.items()}
    print(
        f"edit with another material's faces (a tenth of {len(positions)} vertices, others=), walks and own light: "
        f"median {med['scale']:.2f} ms a Scale edit, {med['colour']:.2f} ms a Base Color edit (both colours per "
        f"vertex instead {med['per_vertex']:.2f} ms); every face the material {med['uniform']:.2f} ms, over {edits} "
        f"edits [budget 5 ms]"
    )


def gpu_edits(label, edit, prt, edits) -> None:
    """Times `edits` GPU edits and prints the medians, transfers and dispatch apart."""
    parts = {k: [] for k in ("fit_seconds", "upload_seconds", "dispatch_seconds", "readback_seconds", "seconds")}
    for k in range(edits):
        edit(k)
        for key in parts:
            parts[key].append(prt.last_eval[key])
    med = {k: 1e3 * statistics.median(v) for k, v in parts.items()}
    print(
        f"{label}: median {med['seconds']:.2f} ms (fit {med['fit_seconds']:.3f}, upload "
        f"{med['upload_seconds']:.3f}, dispatch+wait {med['dispatch_seconds']:.2f}, readback "
        f"{med['readback_seconds']:.2f} ms) over {edits} edits"
    )


def floor_bounce(p, t, marble, args) -> None:
    """The rest of the scene (issue 30): the bunny on a 1 m floor just below it, the floor a
    shadow only (albedo 0) and sending light back (albedo 0.5, one diffuse bounce); the dipole's
    precompute, so the irradiance is most of what differs."""
    lo, hi = p.min(axis=0), p.max(axis=0)
    c, z = 0.5 * (lo + hi), float(lo[2]) - 1e-3
    floor = np.array([[c[0] - 0.5, c[1] - 0.5, z], [c[0] + 0.5, c[1] - 0.5, z],
                      [c[0] + 0.5, c[1] + 0.5, z], [c[0] - 0.5, c[1] + 0.5, z]], np.float32)
    for albedo in (0.0, 0.5):
        scene = models.standard_scene(p, t)
        scene.add_occluder(floor, np.array([[0, 1, 2], [0, 2, 3]]), name="floor", albedo=albedo)
        times, r = [], None
        for _ in range(args.runs):
            t0 = time.perf_counter()
            r = translucent.Prt(scene, marble, coefficients=32, profile="dipole", single_scattering=False).report
            times.append(time.perf_counter() - t0)
        print(f"bunny on a floor of albedo {albedo}: dipole precompute median {statistics.median(times):.2f} s over "
              f"{args.runs} runs (irradiance {r['seconds_irradiance']:.2f} s, {r['rays'] / 1e6:.1f} M rays)")


def single_scattering(big, positions, marble, skin, args) -> None:
    """MS + SS with the dipole on the >= 120k-vertex bunny: precompute and one edit, CPU."""
    t0 = time.perf_counter()
    prt = translucent.Prt(big, [marble, skin], coefficients=32, samples=BIG_SAMPLES, backend="cpu",
                          profile="dipole", single_scattering=True)
    total = time.perf_counter() - t0
    r, ss = prt.report, prt.report["single"]
    print(
        f"\nMS + SS precompute, dipole, {big.vertex_count} vertices: {total:.2f} s "
        f"(single scattering {ss['seconds']:.2f} s: {ss['steps']} steps, {ss['coefficients']} "
        f"coefficients of E, {ss['groups']} light groups, {ss['rays'] / 1e6:.1f} M rays, "
        f"{ss['transport_bytes'] / 1e6:.1f} MB beside MS's {r['transport_bytes'] / 1e6:.1f} MB; "
        f"share {r['single_scattering_share']:.3f}: {r['single_scattering_reason']})"
    )
    eye = positions.mean(axis=0) + np.array([0.05, -0.25, 0.1])
    both, single, ms = [], [], []
    for k in range(args.edits):
        m = marble if k % 2 else skin
        prt.radiance(m, eye=eye)
        both.append(prt.last_eval["seconds"])
        single.append(prt.last_eval["single_seconds"])
        prt.radiosity(m)
        ms.append(prt.last_eval["seconds"])
    print(
        f"MS + SS edit (radiance toward an eye, HG), {big.vertex_count} vertices, CPU: median "
        f"{1e3 * statistics.median(both):.2f} ms (single scattering {1e3 * statistics.median(single):.2f} ms; "
        f"MS alone {1e3 * statistics.median(ms):.2f} ms) over {args.edits} edits [budget 5 ms]; "
        f"S_j in 16-bit fixed point, rounding <= {ss['quantization_error']:.1e} of its vertex's largest S_j,0"
    )
    # The same MS + SS edit through wgpu: both kernels in one submission, one readback wait.
    try:
        where = prt.set_backend("gpu")
    except RuntimeError as e:
        print(f"MS + SS edit on the GPU: skipped ({e})")
        return
    gpu_edits(f"MS + SS edit on {where}", lambda k: prt.radiance(marble if k % 2 else skin, eye=eye), prt,
              args.edits)


if __name__ == "__main__":
    raise SystemExit(main())
