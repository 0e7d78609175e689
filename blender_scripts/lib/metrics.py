"""How the scripts compare one answer with another (docs/design.md, "Error metric"): the
area-weighted relative RMS per channel and its worst channel, the mean ratio, one bake's own
noise read from several seeds, and the image metric over an object's pixels. No Blender."""

from __future__ import annotations

import numpy as np

import translucent


def rel(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> float:
    """Area-weighted relative RMS of a against b, worst channel."""
    return float(max(translucent.relative_error(a, b, w)["rms"]))


def rel_channels(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> list[float]:
    """Area-weighted relative RMS of a against b, per channel."""
    return [float(x) for x in translucent.relative_error(a, b, w)["rms"]]


def worst(err: dict) -> tuple[float, float]:
    """The worst channel's relative RMS and max relative error of a `relative_error` result."""
    return float(max(err["rms"])), float(max(err["max"]))


def ratio(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> list[float]:
    """Area-weighted mean ratio sum(w a) / sum(w b) per channel."""
    return [float((w * a[:, c]).sum() / max((w * b[:, c]).sum(), 1e-30)) for c in range(3)]


def noise_of_one(bakes: list[np.ndarray], w: np.ndarray) -> list[float]:
    """One bake's own noise per channel, from several seeds' bakes of the same thing: the
    area-weighted relative RMS of a bake about the seeds' mean, sqrt(sum_i w_i s_i^2 /
    sum_i w_i mean_i^2) with s_i^2 the seeds' unbiased variance at vertex i."""
    a = np.stack([np.asarray(b, np.float64) for b in bakes])
    mean = a.mean(0)
    var = ((a - mean) ** 2).sum(0) / (len(a) - 1)
    w = np.asarray(w, np.float64)[:, None]
    return np.sqrt((w * var).sum(0) / np.maximum((w * mean ** 2).sum(0), 1e-300)).tolist()


def image_error(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """Relative RMSE and max relative error over the object's pixels (truth alpha > 0.99),
    worst channel (docs/design.md, "Error metric": the image metric)."""
    mask = truth[..., 3] > 0.99
    e, t = estimate[mask][:, :3].astype(np.float64), truth[mask][:, :3].astype(np.float64)
    rms = np.sqrt(((e - t) ** 2).mean(axis=0) / np.maximum((t**2).mean(axis=0), 1e-30))
    mx = (np.abs(e - t) / np.maximum(t, 1e-3 * t.max())).max(axis=0)
    return float(rms.max()), float(mx.max())
