"""PRT against the brute-force ground truth on a shared model (issue 3, point 6): area-weighted
relative RMS and max relative error per channel over random receiver vertices, for Jensen's
measured presets under the standard lighting. No Blender."""

from __future__ import annotations

import time

import numpy as np

import translucent
from blender_scripts.lib import models

PRESETS = ("marble", "skin1", "ketchup")


def evaluate(model: str, receivers: int, coefficients: int, rel_tol: float, seed: int = 7,
             profile: str = "cycles") -> list[dict]:
    """One row per preset: PRT's error against `reference_radiosity` at `receivers` random
    vertices of `model` at 10 cm, its own estimate, and the times of both."""
    p, t = models.load(model, diagonal=0.1)
    scene = models.standard_scene(p, t)
    mats = {name: translucent.Material.preset(name, mm_per_unit=1000.0) for name in PRESETS}
    rng = np.random.default_rng(seed)
    idx = np.sort(rng.choice(scene.vertex_count, size=min(receivers, scene.vertex_count), replace=False))
    weights = scene.vertex_areas[idx, 0]
    rows = []
    for name, m in mats.items():
        t0 = time.perf_counter()
        # The ground truth integrates the direct-light model: PRT without the object's own light.
        prt = translucent.Prt(scene, m, coefficients=coefficients, profile=profile, interreflection=False,
                              walks=0 if profile == "cycles" else None)
        pre = time.perf_counter() - t0
        b = prt.radiosity(m)[idx]
        edit = prt.last_eval["seconds"]
        t0 = time.perf_counter()
        ref, info = translucent.reference_radiosity(scene, m, rel_tol=rel_tol, receivers=idx.tolist(), details=True,
                                                    profile=profile)
        ref_s = time.perf_counter() - t0
        err = translucent.relative_error(b, ref, weights)
        rows.append(
            dict(material=name, rms=err["rms"], max=err["max"], precompute_s=pre, edit_ms=1e3 * edit,
                 reference_s=ref_s, reference_error=info["estimated_rel_error"],
                 reference_level=info["level"], estimate=prt.last_eval["error_estimate"])
        )
    return rows
