"""The in-house ground truth the scripts measure against: `translucent.reference_radiosity`
cached on disk under out/cache/reference/<key>.npz (the key hashes the scene, the material and
the settings), and the weight that turns its radiosity into what a vertex bake sees along the
normal. No Blender."""

from __future__ import annotations

import hashlib
import json
import pathlib
import time

import numpy as np

import translucent

REPO = pathlib.Path(__file__).resolve().parents[2]
CACHE = REPO / "out" / "cache"


def digest(*parts) -> str:
    """A short hash of arrays (their bytes) and anything else (its repr): a cache key."""
    h = hashlib.sha256()
    for p in parts:
        h.update(p.tobytes() if isinstance(p, np.ndarray) else repr(p).encode())
    return h.hexdigest()[:24]


def ground_truth(scene_key: str, scene, material, receivers: np.ndarray, rel_tol: float,
                 profile: str = "cycles") -> tuple[np.ndarray, float, dict]:
    """The reference radiosity of `profile` at `receivers`, cached on disk by scene, material
    and settings: the values, the wall time of the original computation [s] and its details."""
    layers = (material.roughness, material.subsurface_weight, material.metallic, material.transmission,
              material.base_color)
    key = digest(scene_key, material.sigma_a, material.sigma_s, material.g, material.eta, receivers, rel_tol,
                 *((profile, layers) if profile != "dipole" else ()))
    path = CACHE / "reference" / f"{key}.npz"
    if path.exists():
        z = np.load(path, allow_pickle=False)
        return z["values"], float(z["seconds"]), json.loads(str(z["info"]))
    t0 = time.perf_counter()
    values, info = translucent.reference_radiosity(
        scene, material, rel_tol=rel_tol, receivers=receivers.tolist(), details=True, profile=profile
    )
    seconds = time.perf_counter() - t0
    info = {k: (v if isinstance(v, (int, float, bool, str)) else str(v)) for k, v in info.items()}
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, values=values, seconds=seconds, info=json.dumps(info))
    return values, seconds, info


def fresnel_t(eta: float) -> float:
    """F_t at normal incidence, 1 - ((eta - 1) / (eta + 1))^2: radiance along the normal is
    F_t B / pi (Xu 2007 eq. 2), what a vertex bake sees."""
    return 1.0 - ((eta - 1.0) / (eta + 1.0)) ** 2


def exit_weight(material, profile: str) -> float:
    """W with L = W B / pi along the normal (what a vertex bake sees of radiosity B): what the
    Principled specular layer leaves at normal view for Cycles' profile, F_t(0) for the dipole."""
    return translucent.layer_weight(material.roughness, 1.0, material.eta) if profile == "cycles" else fresnel_t(
        material.eta)
