"""Error against run time (issue 5, point 3; issue 9, point 7; issue 31): every method (PRT,
the hierarchy, the splatting with eps and Shah's Fig. 12 grids as its knobs), setting and
profile measured against the brute-force ground truth of the same profile
(`translucent.reference_radiosity`) and against Cycles, next to the wall time of its precompute
and of one edit. Both profiles are measured: Cycles' random walk (the default: PRT with the
object's own light) and Jensen's dipole (the papers' model). Cycles at several
sample counts is its own curve (error against a high-sample Cycles bake), and EEVEE's own
subsurface render is the peer an artist would otherwise use.

Outputs in --out (default out/report): report.csv, report.png (log-log), report.md.
Ground truth and Cycles results are cached under out/cache, so a second run re-renders
nothing. Error metric (docs/design.md, "Error metric"): area-weighted relative RMS over the
receiver vertices and max relative error, worst channel; for images, relative RMSE over the
object's pixels.

Run: .venv/bin/python blender_scripts/report.py [--materials marble skin1 ketchup]
     [--receivers 100] [--model suzanne | stanford-bunny.obj ...] [--no-cycles] [--no-eevee]
     [--scene-materials marble skin1 | --no-scene]
"""

from __future__ import annotations

import argparse
import csv
import pathlib
import sys
import time
from dataclasses import asdict, dataclass, field

import numpy as np

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import bpy  # noqa: E402,F401

import translucent  # noqa: E402
from addon import export  # noqa: E402
from blender_scripts.lib import cycles_reference as cr  # noqa: E402
from blender_scripts.lib import scene_parts, scenes  # noqa: E402
from blender_scripts.lib.ground_truth import digest, exit_weight, ground_truth  # noqa: E402
from blender_scripts.lib.machine import cpu_and_cores  # noqa: E402
from blender_scripts.lib.metrics import image_error, worst  # noqa: E402

# PRT settings swept: (basis size, degree, fit tolerance or None).
PRT_SETTINGS = [(8, 1, None), (16, 1, None), (32, 1, None), (64, 1, None), (16, 2, None), (32, 2, None),
                (64, 1, 0.02), (64, 1, 0.005)]


@dataclass
class Row:
    method: str
    setting: str
    material: str
    against: str  # "ground truth" or "Cycles <spp> spp"
    rms: float  # worst channel, relative
    max: float
    precompute_s: float = 0.0
    edit_s: float = 0.0
    estimate: float = float("nan")  # the method's own error estimate, worst channel
    notes: str = ""
    extra: dict = field(default_factory=dict)

    @property
    def time_s(self) -> float:
        return self.precompute_s + self.edit_s


def progress(i: int, n: int, what: str) -> None:
    """A one-line progress bar on stderr for the long runs."""
    width = 30
    done = int(width * i / max(n, 1))
    print(f"\r[{'#' * done}{'.' * (width - done)}] {i}/{n} {what[:60]:60s}", end="", file=sys.stderr, flush=True)
    if i == n:
        print(file=sys.stderr)


# Ray budgets of the walks through the mesh in the report (0: the half-space table alone; 30 M is
# the default).
WALK_RAYS = (0, 5_000_000, 30_000_000, 60_000_000)


def timed_edits(prt, edit, runs: int = 5):
    """The last of `runs` edits and the median of their times in the core [s]."""
    times = []
    for _ in range(runs):
        out = edit()
        times.append(prt.last_eval["seconds"])
    return out, float(np.median(times))


def prt_rows(scene, material, name, truth, receivers, weights, cycles=None, profile="cycles") -> list[Row]:
    """Each PRT setting: one precompute for the material, one (timed) edit, the errors against
    the ground truth (direct light, as the reference integrates it) and, with the object's own
    light as Cycles has it, against Cycles."""
    rows = []
    method = f"PRT (Xu 2007), {profile} profile"
    for coefficients, degree, fit_tol in PRT_SETTINGS:
        t0 = time.perf_counter()
        # Against the ground truth of the half-space profile: no walks through the mesh here.
        prt = translucent.Prt(scene, material, coefficients=coefficients, degree=degree,
                              fit_tolerance=fit_tol, backend="cpu", profile=profile, interreflection=False,
                              walks=0 if profile == "cycles" else None)
        pre = time.perf_counter() - t0
        b, edit_s = timed_edits(prt, lambda: prt.radiosity(material))
        est = max(prt.last_eval["error_estimate"])
        rep = prt.report
        setting = f"{rep['coefficients']} coeff., degree {degree}" + (f", fit tol. {fit_tol:g}" if fit_tol else "")
        rms, mx = worst(translucent.relative_error(b[receivers], truth, weights))
        rows.append(Row(method, setting, name, "ground truth", rms, mx, pre, edit_s, est,
                        extra=dict(samples=rep["samples"], coefficients=rep["coefficients"])))
        if cycles is not None and (coefficients, degree, fit_tol) == (32, 1, None):
            # The walks' knob (issue 12): rays they may cast, 0 for the half-space table alone.
            for walk_rays in (WALK_RAYS if profile == "cycles" else (None,)):
                t0 = time.perf_counter()
                full = translucent.Prt(scene, material, coefficients=coefficients, degree=degree, backend="cpu",
                                       profile=profile, interreflection=profile == "cycles",
                                       walks=0 if walk_rays == 0 else None, walk_rays=walk_rays or None,
                                       single_scattering=False)  # MS alone, as the rows above
                pre_full = time.perf_counter() - t0
                radiance = full.radiance(material)
                edit = full.last_eval["seconds"]
                rms, mx = worst(translucent.relative_error(radiance, cycles["all"], cycles["weights"]))
                bounce = ", with the object's own light" if full.report["interreflection_rays"] else ""
                w = full.report["walks"]
                walks = (f", walks {w['walks_per_vertex']} x {w['walked_vertices']} vertices "
                         f"({w['rays'] / 1e6:.0f} M rays, {w['skipped_flat']} flat skipped)") if w else (
                    ", half-space table alone" if profile == "cycles" else "")
                rows.append(Row(method, setting + bounce + walks, name, cycles["label"] + ", all vertices", rms, mx,
                                pre_full, edit, max(full.last_eval["error_estimate"]),
                                notes="what the artist sees against what Cycles renders"))
            if profile == "dipole":
                rows += single_rows(scene, material, name, receivers, weights, cycles, coefficients, degree)
    return rows


# Basis sizes of single scattering's E swept, as Xu 2007 Fig. 4.
SINGLE_COEFFICIENTS = (6, 8, 16, 32)


def single_rows(scene, material, name, receivers, weights, cycles, coefficients, degree) -> list[Row]:
    """Issue 11: the dipole's MS + SS (Xu 2007 eq. 1) at 6, 8, 16 and 32 coefficients of E,
    L^(1) against its brute-force integral of eq. 5 (`reference_single_scattering`, along the
    normal as a bake sees it) and MS + SS against Cycles, beside the MS-alone row above."""
    rows = []
    method = "PRT (Xu 2007), dipole profile, MS + SS"
    t0 = time.perf_counter()
    want = translucent.reference_single_scattering(scene, material, receivers=receivers)
    ref_s = time.perf_counter() - t0
    for k in SINGLE_COEFFICIENTS:
        t0 = time.perf_counter()
        prt = translucent.Prt(scene, material, coefficients=coefficients, degree=degree, backend="cpu",
                              profile="dipole", interreflection=False, single_scattering=True,
                              single_coefficients=k)
        pre = time.perf_counter() - t0
        radiance, edit_s = timed_edits(prt, lambda: prt.radiance(material))
        est = max(prt.last_eval["single_error_estimate"])
        l1 = prt.single_radiance(material)
        setting = f"{k} coefficients of E (MS: {coefficients})"
        rms, mx = worst(translucent.relative_error(l1[receivers], want, weights))
        rows.append(Row(method, setting + ", L1 alone", name, "ground truth (single scattering)", rms, mx,
                        pre, edit_s, est, notes=f"brute force of eq. 5: {ref_s:.1f} s"))
        rms, mx = worst(translucent.relative_error(radiance, cycles["all"], cycles["weights"]))
        rows.append(Row(method, setting, name, cycles["label"] + ", all vertices", rms, mx, pre,
                        edit_s, est, notes="MS + SS against what Cycles renders"))
    return rows


# The hierarchy's receiver threshold eps1 swept (eps2 at its default 0.5): Mertens 2003 §3.2.
HIERARCHY_EPS = ((0.02, 0.5), (0.01, 0.5), (0.005, 0.5), (0.0025, 0.5))


def hierarchy_rows(scene, material, name, truth, receivers, weights, cycles=None, profile="cycles") -> list[Row]:
    """The hierarchy (Mertens 2003) at each eps: built on the fly (timed), then one timed
    re-evaluation for the material; against the ground truth (direct light, the same model) and,
    at the default, against Cycles along the normal (no walks, no object's own light)."""
    rows = []
    method = f"Hierarchy (Mertens 2003), {profile} profile"
    for eps in HIERARCHY_EPS:
        t0 = time.perf_counter()
        # The world shadowed, as the ground truth and Cycles have it (the default's nine SH
        # coefficients leave the mesh's own occlusion of the world out).
        h = translucent.Hierarchy(scene, material, profile=profile, eps=eps, mode="on_the_fly",
                                  world_shadows=True)
        pre = time.perf_counter() - t0
        evals = []
        for _ in range(3):
            t1 = time.perf_counter()
            b = h.radiosity(material)
            evals.append(time.perf_counter() - t1)
        rep = h.report
        rms, mx = worst(translucent.relative_error(b[receivers], truth, weights))
        setting = f"eps {eps[0]:g}, {eps[1]:g}: {rep['links']} links ({rep['links_per_face']:.0f} per face)"
        rows.append(Row(method, setting, name, "ground truth", rms, mx, pre, float(np.median(evals)),
                        float(max(rep["error_estimate"])), extra=dict(links=rep["links"])))
        if cycles is not None and eps == (0.005, 0.5):
            radiance = h.radiance(material, None)
            rms, mx = worst(translucent.relative_error(radiance, cycles["all"], cycles["weights"]))
            rows.append(Row(method, setting, name, cycles["label"] + ", all vertices", rms, mx, pre,
                            float(np.median(evals)), notes="direct light through a half-space profile, no walks"))
    return rows


# The splatting's knob (Shah 2009 eqs. 4-5) at the default grid, then Shah's Fig. 12 grids.
SPLAT_SETTINGS = ((0.1, 1024), (0.03, 1024), (0.01, 1024), (0.003, 1024), (0.01, 8), (0.01, 16), (0.01, 32))


def splat_rows(scene, material, name, truth, receivers, weights, cycles=None, profile="cycles") -> list[Row]:
    """The splatting (Shah 2009) at each (eps, grid): nothing precomputed, each evaluation timed
    whole (its own error estimate included); against the ground truth and, at the default with
    the walks' term and own light (Cycles' profile), against Cycles along the normal."""
    rows = []
    method = f"Splatting (Shah 2009), {profile} profile"
    for eps, grid in SPLAT_SETTINGS:
        splat = translucent.Splat(scene, profile=profile, eps=eps, max_grid=grid)
        b = splat.radiosity(material)
        ev, r = splat.last_eval, splat.report
        rms, mx = worst(translucent.relative_error(b[receivers], truth, weights))
        setting = f"eps {eps:g}, grid {grid}: {r['splats']:,} splats"
        rows.append(Row(method, setting, name, "ground truth", rms, mx, 0.0, ev["seconds"],
                        float(max(ev["error_estimate"])), extra=dict(splats=r["splats"])))
        if cycles is not None and profile == "cycles" and (eps, grid) == (0.01, 1024):
            walked = translucent.Splat(scene, profile=profile, eps=eps, max_grid=grid, walks=True)
            t0 = time.perf_counter()
            radiance = walked.radiance(material)
            first = time.perf_counter() - t0
            rms, mx = worst(translucent.relative_error(radiance, cycles["all"], cycles["weights"]))
            rows.append(Row(method, setting + ", walks and own light", name, cycles["label"] + ", all vertices",
                            rms, mx, first - walked.last_eval["seconds"], walked.last_eval["seconds"],
                            notes="what the artist sees against what Cycles renders (walks traced once: "
                                  "'precompute')"))
    return rows


def cycles_rows(obj, material, name, spp_list, reference_spp, receivers, weights):
    """Cycles vertex bakes at each sample count against the high-sample bake, on another
    sampling seed than it (`LADDER_SEED`)."""
    ref, ref_s = cr.bake_vertices(obj, material, reference_spp)
    label = f"Cycles {reference_spp} spp"
    rows = []
    for spp in spp_list:
        values, seconds = cr.bake_vertices(obj, material, spp, seed=cr.LADDER_SEED)
        rms, mx = worst(translucent.relative_error(values[receivers], ref[receivers], weights))
        rows.append(Row("Cycles random walk (bake)", f"{spp} spp", name, label, rms, mx, seconds, 0.0,
                        notes="vertex bake, diffuse passes"))
    return rows, dict(values=ref[receivers], all=ref, label=label, seconds=ref_s)


def eevee_rows(obj, material, name, samples_list, reference_spp):
    """EEVEE's own subsurface scattering against a high-sample Cycles render of the camera view."""
    try:
        truth, _ = cr.render_image(obj, material, reference_spp, "CYCLES")
        rows = []
        for samples in samples_list:
            img, seconds = cr.render_image(obj, material, samples, "EEVEE")
            rms, mx = image_error(img, truth)
            rows.append(Row("EEVEE", f"{samples} samples", name, f"Cycles {reference_spp} spp image", rms, mx,
                            seconds, 0.0, notes="128 px render, object pixels"))
        return rows
    except RuntimeError as e:
        print(f"EEVEE skipped: {e}", file=sys.stderr)
        return []


SCENE_METHOD = "PRT in a scene (issue 30)"


def scene_rows(materials: list[str], spp: int) -> list[Row]:
    """Issue 30's scenes, each preview a row split by the part it adds (`scene_parts.measure`),
    against a Cycles bake of the whole scene at `spp`, every sample taken. Builds a new Blender
    file: run it last."""
    rows = []
    for p in scene_parts.measure(materials, spp, log=lambda line: print(line, file=sys.stderr, flush=True)):
        rows.append(Row(SCENE_METHOD, f"{p.scene}, {p.obj}: {p.part}", p.material,
                        f"Cycles {spp} spp, whole scene, every sample", p.rms, p.max, p.precompute_s, p.edit_s,
                        p.estimate, notes=f"{p.vertices} vertices compared; bake {p.bake_s:.0f} s",
                        extra=dict(scene=p.scene, part=p.part, obj=p.obj, chain=p.chain)))
    return rows


def scene_table(rows: list[Row]) -> list[str]:
    """report.md's section for the scene rows: each part's distance and what it changed against
    the row before it in the same scene, object and material."""
    ours = [r for r in rows if r.method == SCENE_METHOD]
    if not ours:
        return []
    lines = ["", "## In an artist's scene, split by part (issue 30)", "",
             "Each row adds one part to the row before it in the same scene (textures: to the socket's "
             "value shown uniformly; object IDs: to the two merged into one medium; material slots: to "
             "every face previewed).", "",
             "| scene | object | material | part | rel. RMS % | change, points | precompute s | edit ms | "
             "own estimate % |", "|---|---|---|---|---|---|---|---|---|"]
    before: dict[tuple, float] = {}
    for r in ours:
        key = (r.extra["scene"], r.extra["obj"], r.material, r.extra["chain"])
        change = "" if key not in before or not r.extra["part"].startswith("+") else \
            f"{100 * (r.rms - before[key]):+.2f}"
        before[key] = r.rms
        lines.append(f"| {r.extra['scene']} | {r.extra['obj']} | {r.material} | {r.extra['part']} | "
                     f"{100 * r.rms:.2f} | {change} | {r.precompute_s:.1f} | {1e3 * r.edit_s:.2f} | "
                     f"{100 * r.estimate:.2f} |")
    return lines


def write_outputs(rows: list[Row], out: pathlib.Path, title: str) -> None:
    out.mkdir(parents=True, exist_ok=True)
    fields = ["method", "setting", "material", "against", "rms", "max", "precompute_s", "edit_s", "time_s",
              "estimate", "notes"]
    with open(out / "report.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(fields)
        for r in rows:
            d = asdict(r)
            d["time_s"] = r.time_s
            w.writerow([d[k] for k in fields])

    lines = [f"# {title}", "",
             "| method | setting | material | against | rel. RMS % | max rel. % | precompute s | edit ms | "
             "own estimate % | notes |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r.method == SCENE_METHOD:
            continue  # their own table below
        est = "" if np.isnan(r.estimate) else f"{100 * r.estimate:.2f}"
        edit = f"{1e3 * r.edit_s:.2f}" if r.edit_s else ""
        lines.append(f"| {r.method} | {r.setting} | {r.material} | {r.against} | {100 * r.rms:.2f} | "
                     f"{100 * r.max:.1f} | {r.precompute_s:.2f} | {edit} | {est} | {r.notes} |")
    lines += scene_table(rows)
    (out / "report.md").write_text("\n".join(lines) + "\n")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(14, 6.5))
    materials = sorted({r.material for r in rows})
    colours = dict(zip(materials, plt.rcParams["axes.prop_cycle"].by_key()["color"]))
    for mat in materials:
        c = colours[mat]
        for profile, marker in (("cycles", "o"), ("dipole", "D")):
            ours = [r for r in rows if r.method.startswith("PRT") and profile in r.method and r.material == mat]
            prt = [r for r in ours if r.against == "ground truth"]
            if prt:
                ax.scatter([r.edit_s for r in prt], [r.rms for r in prt], color=c, marker=marker,
                           label=f"PRT edit, {profile}, {mat} (vs its ground truth)")
                ax.scatter([r.precompute_s for r in prt], [r.rms for r in prt], color=c, marker=marker,
                           facecolors="none", label=f"PRT precompute, {profile}, {mat}")
            prt_c = [r for r in ours if r.against.startswith("Cycles")]
            if prt_c:
                ax.scatter([r.edit_s for r in prt_c], [r.rms for r in prt_c], color=c,
                           marker="^" if profile == "cycles" else "v", s=60,
                           label=f"PRT edit, {profile}, {mat} (vs Cycles)")
            for prefix, mk, mk_cycles, what in (("Hierarchy", "h", "p", "hierarchy evaluation"),
                                                ("Splatting", "x", "P", "splatting evaluation (eps, grid)")):
                theirs = [r for r in rows if r.method.startswith(prefix) and profile in r.method
                          and r.material == mat]
                for against, filled in (("ground truth", True), ("Cycles", False)):
                    pts = [r for r in theirs if r.against.startswith(against)]
                    if pts:
                        ax.scatter([r.edit_s for r in pts], [r.rms for r in pts], color=c,
                                   marker=mk if filled else mk_cycles, s=40,
                                   label=f"{what}, {profile}, {mat} (vs {against})")
        cyc = sorted((r for r in rows if r.method.startswith("Cycles") and r.material == mat), key=lambda r: r.time_s)
        if cyc:
            ax.plot([r.time_s for r in cyc], [r.rms for r in cyc], color=c, marker="s", linestyle="--",
                    label=f"Cycles bake by spp, {mat}")
        for scene_name, marker in ((scene_parts.FLOOR, "d"), (scene_parts.TEXTURE, "<"),
                                   (scene_parts.TOUCHING, ">"), (scene_parts.SLOTS, "8")):
            pts = [r for r in rows if r.method == SCENE_METHOD and r.material == mat
                   and r.extra["scene"] == scene_name]
            if pts:
                # Each part's precompute and edit against its distance; a dotted line runs through
                # the parts in the order they are added.
                ax.plot([r.time_s for r in pts], [r.rms for r in pts], color=c, marker=marker, linestyle=":",
                        markersize=7, label=f"PRT in a scene {scene_name.split(' ')[0]}, {mat}: part by part "
                                            "(precompute)")
        eevee = [r for r in rows if r.method.startswith("EEVEE") and r.material == mat]
        if eevee:
            ax.scatter([r.time_s for r in eevee], [r.rms for r in eevee], color=c, marker="*", s=120,
                       label=f"EEVEE render, {mat}")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time [s] (filled: one edit; hollow: precompute; Cycles/EEVEE: render)")
    ax.set_ylabel("relative RMS error (worst channel)")
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    # Outside the axes, on the right: the points stay visible.
    ax.legend(fontsize=6, loc="upper left", bbox_to_anchor=(1.01, 1.0), ncol=2, frameon=False)
    fig.tight_layout()
    fig.savefig(out / "report.png", dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=str(REPO / "out" / "report"))
    ap.add_argument("--model", default="suzanne", help="'suzanne' (built in) or a file in ../shared/models")
    ap.add_argument("--materials", nargs="+", default=["marble", "skin1", "ketchup"])
    ap.add_argument("--receivers", type=int, default=100, help="vertices the ground truth is computed at")
    ap.add_argument("--rel-tol", type=float, default=2e-3, help="ground truth tolerance")
    ap.add_argument("--no-cycles", action="store_true")
    ap.add_argument("--no-eevee", action="store_true")
    ap.add_argument("--spp", type=int, nargs="+", default=[4, 16, 64, 256], help="Cycles bake sample counts")
    ap.add_argument("--reference-spp", type=int, default=1024, help="the high-sample Cycles bake and image")
    ap.add_argument("--eevee-samples", type=int, nargs="+", default=[16, 64])
    ap.add_argument("--profiles", nargs="+", default=["cycles", "dipole"], choices=["cycles", "dipole"])
    ap.add_argument("--scene-materials", nargs="+", default=["marble", "skin1"],
                    help="issue 30's scenes in these materials (the touching ball in the second)")
    ap.add_argument("--no-scene", action="store_true", help="leave issue 30's scenes out")
    args = ap.parse_args(argv)
    out = pathlib.Path(args.out)

    obj, cam = scenes.build_scene(args.model)
    scene, info = export.export_scene([obj])
    bake_obj = None
    if not (args.no_cycles and args.no_eevee):
        bake_obj = scenes.preview_object(obj)  # the evaluated mesh as its own object (same vertices)
        bake_obj.data.materials.clear()
    p = np.asarray(scene.vertex_areas)  # part of the cache key via the scene digest below
    scene_key = digest(args.model, scene.vertex_count, scene.triangle_count, p, info.lights, info.world)
    rng = np.random.default_rng(1)
    receivers = np.sort(rng.choice(scene.vertex_count, size=min(args.receivers, scene.vertex_count), replace=False))
    weights = scene.vertex_areas[receivers, 0]
    rows: list[Row] = []
    steps = len(args.materials)
    for i, name in enumerate(args.materials):
        m = translucent.Material.preset(name, scenes.MM_PER_UNIT)
        cyc = None
        if not args.no_cycles:
            progress(i, steps, f"{name}: Cycles bakes")
            rows_c, cyc = cycles_rows(bake_obj, m, name, args.spp, args.reference_spp, receivers, weights)
            cyc["weights"] = scene.vertex_areas[:, 0]
            rows += rows_c
        for profile in args.profiles:
            progress(i, steps, f"{name}: ground truth, {profile}")
            truth, ref_s, ref_info = ground_truth(scene_key, scene, m, receivers, args.rel_tol, profile)
            if cyc is not None:
                # The model itself (direct light, integrated exactly) against Cycles, along the normal.
                w = exit_weight(m, profile)
                rms, mx = worst(translucent.relative_error(truth * (w / np.pi), cyc["values"], weights))
                rows.append(Row(f"{profile.capitalize()} ground truth", "direct light, exact integral", name,
                                cyc["label"], rms, mx, ref_s, 0.0,
                                notes="the model's distance from Cycles' random walk (no interreflection)"))
            progress(i, steps, f"{name}: PRT settings, {profile}")
            rows += prt_rows(scene, m, name, truth, receivers, weights, cyc, profile)
            progress(i, steps, f"{name}: hierarchy thresholds, {profile}")
            rows += hierarchy_rows(scene, m, name, truth, receivers, weights, cyc, profile)
            progress(i, steps, f"{name}: splatting thresholds and grids, {profile}")
            rows += splat_rows(scene, m, name, truth, receivers, weights, cyc, profile)
            rows.append(Row(f"Reference (brute force), {profile}", f"rel. tol. {args.rel_tol:g}, level "
                            f"{ref_info.get('level')}", name, "ground truth",
                            float(ref_info.get("estimated_rel_error", 0.0)), float("nan"), ref_s, 0.0,
                            notes="its own convergence estimate"))
        if not args.no_eevee:
            progress(i, steps, f"{name}: EEVEE")
            rows += eevee_rows(bake_obj, m, name, args.eevee_samples, args.reference_spp)
    if not args.no_scene and not args.no_cycles:
        progress(steps, steps, "issue 30's scenes, part by part")
        rows += scene_rows(args.scene_materials, args.reference_spp)
    progress(steps, steps, "done")
    title = (f"{args.model}: {scene.vertex_count} vertices, {len(receivers)} receivers; "
             f"{cpu_and_cores()}; PRT edits on the CPU, median of 5")
    write_outputs(rows, out, title)
    print((out / "report.md").read_text())
    print(f"CSV, PNG and Markdown in {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
