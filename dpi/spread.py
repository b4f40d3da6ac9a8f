"""How much posterior samples differ: scale-free maps compared across samples (sigma2_sample).

Illumination is known only up to a global scale, so maps are compared after dividing by their median
luminance and tone mapping; the variance across samples, per element and averaged, is the paper's
sigma2_sample. Used by the summary, the adaptive stop rule and the studies alike.
"""

from __future__ import annotations

import numpy as np
import torch

from dpi.envmap import texel_solid_angles
from dpi.exposure import robust_level
from dpi.images import luminance, resize, tonemap


def normalized_env(env: np.ndarray) -> np.ndarray:
    """Env map divided by its median (positive) luminance, tone-mapped: scale-free, for spread across samples."""
    return tonemap(env / (robust_level(luminance(env)) or 1.0))


def sample_variance(samples: list[np.ndarray]) -> float:
    """Per-element variance across samples, averaged (sigma2_sample); 0 for a single sample."""
    if len(samples) < 2:
        return 0.0
    return float(np.stack(samples).var(axis=0, ddof=1).mean())


LOG_FLOOR = 1e-4
"""radiance floor, times a map's median luminance, before the logarithm"""


def log_radiance(env: np.ndarray, height: int) -> np.ndarray:
    """(height, 2 height, 3) log radiance of a map, area-resampled to `height`, floored at LOG_FLOOR x its median."""
    env = resize(torch.from_numpy(np.ascontiguousarray(env, np.float32)), height, 2 * height).double().numpy()
    floor = LOG_FLOOR * (robust_level(luminance(env)) or 1.0)
    return np.log(np.maximum(env, floor))


def aligned_log_maps(samples: list[np.ndarray], truth: np.ndarray) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """The samples' and the truth's log radiance at the samples' resolution, each sample shifted by the global
    log scale that best matches the truth (solid-angle weighted least squares), and the texel weights (H, 1)."""
    height = samples[0].shape[0]
    weights = texel_solid_angles(height)
    weights = weights / (weights.sum() * 2 * height)
    reference = log_radiance(truth, height)
    aligned = []
    for sample in samples:
        log_sample = log_radiance(sample, height)
        shift = float((weights[..., None] * (reference - log_sample)).sum() / 3)
        aligned.append(log_sample + shift)
    return aligned, reference, weights


def log_distance(a: np.ndarray, b: np.ndarray, weights: np.ndarray) -> float:
    """Solid-angle weighted mean squared difference of two log-radiance maps (per texel and channel)."""
    return float((weights[..., None] * (a - b) ** 2).sum() / 3)


def calibration(samples: list[np.ndarray], truth: np.ndarray) -> float:
    """Mean distance of the samples to the truth over their mean pairwise distance (log radiance, scale-aligned
    to the truth): ~1 when the truth looks like one more sample, >> 1 when the samples collapse onto one guess
    (needs 2 samples; nan for fewer)."""
    if len(samples) < 2:
        return float("nan")
    aligned, reference, weights = aligned_log_maps(samples, truth)
    to_truth = np.mean([log_distance(s, reference, weights) for s in aligned])
    pairs = [log_distance(a, b, weights) for i, a in enumerate(aligned) for b in aligned[i + 1:]]
    return float(to_truth / max(np.mean(pairs), 1e-30))


def log_std_map(samples: list[np.ndarray]) -> np.ndarray:
    """(H, 2H) per-texel std across samples of the log luminance, each sample divided by its median first:
    where the photos do not tell the light (the uncertainty map)."""
    logs = [np.log(np.maximum(luminance(s), LOG_FLOOR * (robust_level(luminance(s)) or 1.0))
                   / (robust_level(luminance(s)) or 1.0)) for s in samples]
    return np.stack(logs).std(axis=0, ddof=1) if len(logs) > 1 else np.zeros_like(logs[0])
