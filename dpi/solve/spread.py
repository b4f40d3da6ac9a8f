"""How much posterior samples differ: scale-free maps compared across samples (sigma2_sample).

Illumination is known only up to a global scale, so maps are compared after dividing by their median
luminance and tone mapping; the variance across samples, per element and averaged, is the paper's
sigma2_sample. Used by the summary, the adaptive stop rule and the studies alike.
"""

from __future__ import annotations

import numpy as np
import torch

from dpi.io.images import luminance, resize, tonemap
from dpi.light.envmap import texel_solid_angles
from dpi.solve.exposure import robust_level


def median_level(env: np.ndarray) -> float:
    """An env map's median (positive) luminance, 1 for a black map: the scale that comparisons across samples
    divide out."""
    return robust_level(luminance(env)) or 1.0


def normalized_env(env: np.ndarray) -> np.ndarray:
    """Env map divided by its median (positive) luminance, tone-mapped: scale-free, for spread across samples."""
    return tonemap(env / median_level(env))


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
    return np.log(np.maximum(env, LOG_FLOOR * median_level(env)))


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


def mean_log_map(samples: list[np.ndarray]) -> np.ndarray:
    """(H, 2H, 3) geometric mean of env maps, each divided by its median luminance first (at median ~1): what
    the samples share, their mean in log radiance. Of calibrated samples each as far from the truth as from
    another, it is nearer the truth than any one of them (README, Outputs)."""
    return np.exp(np.mean([np.log(np.maximum(s / median_level(s), LOG_FLOOR)) for s in samples], axis=0))


def normalized_albedo(albedo: np.ndarray) -> np.ndarray:
    """Albedo divided by its mean: scale-free (light and albedo trade a global factor), for spread across samples."""
    return albedo / max(float(albedo.mean()), 1e-6)


def _std_across(maps: list[np.ndarray]) -> np.ndarray:
    """Per-element std across maps (ddof 1); needs 2 maps, since one sample says nothing about its spread."""
    if len(maps) < 2:
        raise ValueError(f"the spread of samples needs 2 or more, got {len(maps)}")
    return np.stack(maps).std(axis=0, ddof=1)


def log_std_map(samples: list[np.ndarray]) -> np.ndarray:
    """(H, 2H) per-texel std across env maps of the log luminance, each divided by its median first: where the
    photos do not tell the light (0.7 is a factor of 2 either way)."""
    return _std_across([np.log(np.maximum(luminance(s) / median_level(s), LOG_FLOOR)) for s in samples])


def albedo_std_map(samples: list[np.ndarray]) -> np.ndarray:
    """(H, W) per-texel std across albedo textures of their luminance, each divided by its mean: where the
    photos do not tell the material's colour apart from the light's (in units of the mean albedo)."""
    return _std_across([luminance(normalized_albedo(a)) for a in samples])


def roughness_std_map(samples: list[np.ndarray]) -> np.ndarray:
    """(H, W) per-texel std across roughness textures (H, W, C) as read_exr gives them: where the samples read the
    material differently (a mirror and a rough reading of the same views, dpi.solve.init)."""
    return _std_across([r[..., 0] for r in samples])


def sphere_mean(values: np.ndarray) -> float:
    """Solid-angle weighted mean of an (H, 2H) map over the sphere (a map's poles hold little of it)."""
    weights = np.broadcast_to(texel_solid_angles(values.shape[0]), values.shape)
    return float((weights * values).sum() / weights.sum())
