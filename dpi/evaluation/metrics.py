"""Image, environment-map and albedo metrics, with the scale alignment the comparisons need.

Illumination and albedo are only known up to a global scale (a brighter map and a darker
albedo render the same image), so:
- env maps are aligned by one global factor s = exp(mean(log Y_gt - log Y_est)) over texels
  (luminance Y, least squares in log space), brought to the reference's exposure-free level (its
  median luminance at MIDDLE_GREY), then tone-mapped with L / (1 + L) before PSNR/SSIM;
- albedos are aligned per channel by the least-squares factor sum(est * gt) / sum(est^2).
Every metric is therefore the same for a capture at any absolute scale, and finite: an exact match
reports PSNR_CAP.
"""

from __future__ import annotations

import numpy as np
import torch
from skimage.metrics import structural_similarity

from dpi.io.images import luminance, resize, tonemap
from dpi.light.envmap import texel_solid_angles
from dpi.solve.exposure import middle_grey_gain, robust_level

EPS = 1e-6
"""log-space guard, relative to a map's level"""
PSNR_CAP = 100.0
"""PSNR (dB) reported for an exact match (MSE 1e-10 of the data range squared), instead of infinity"""


def missing(reason: str) -> str:
    """The value recorded for a metric that could not be computed: never a number."""
    return f"missing: {reason}"


def psnr(a: np.ndarray, b: np.ndarray, mask: np.ndarray | None = None, data_range: float = 1.0) -> float:
    """Peak signal-to-noise ratio in dB over all pixels, or the pixels where `mask` is true; at most PSNR_CAP."""
    diff = (np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2
    if mask is not None:
        diff = diff[mask]
    mse = float(diff.mean())
    return PSNR_CAP if mse <= data_range**2 * 10 ** (-PSNR_CAP / 10) else float(10.0 * np.log10(data_range**2 / mse))


def ssim(a: np.ndarray, b: np.ndarray, data_range: float = 1.0) -> float:
    """Structural similarity of two (H, W, 3) images (scikit-image, Gaussian-free 7x7 window)."""
    win = min(7, *(s - (1 - s % 2) for s in a.shape[:2]))
    return float(structural_similarity(a, b, data_range=data_range, channel_axis=-1, win_size=win))


def resize_image(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """Area-average (down) or bilinear (up) resampling of an (H, W, C) image."""
    if image.shape[:2] == (height, width):
        return image
    return resize(torch.from_numpy(np.ascontiguousarray(image, dtype=np.float32)), height, width).numpy()


def env_scale(estimate: np.ndarray, reference: np.ndarray) -> float:
    """Global factor aligning an env map to a reference (log-space least squares on luminance; the guard
    against black texels is relative to each map's level, so the factor scales exactly with either map)."""
    ye, yr = luminance(estimate), luminance(reference)
    guard_e, guard_r = (EPS * (robust_level(y) or 1.0) for y in (ye, yr))
    return float(np.exp(np.mean(np.log(yr + guard_r) - np.log(ye + guard_e))))


def aligned_env(estimate: np.ndarray, reference: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Tone-mapped scale-aligned estimate and reference (resized to the estimate), both at the reference's
    median luminance MIDDLE_GREY, and the scale aligning the estimate to the reference."""
    reference = resize_image(reference, *estimate.shape[:2])
    s = env_scale(estimate, reference)
    gain = middle_grey_gain(luminance(reference))
    return tonemap(gain * s * estimate), tonemap(gain * reference), s


BALANCE_ROWS = (2, 8)
"""rows of the shrunk maps whose log error is the light's broad balance: sky against ground (2), and the sides and
bands a rough object's shading measures (8)"""
ENV_BALANCE = tuple(f"env_balance_{rows}" for rows in BALANCE_ROWS)
"""env_metrics' balance columns"""


def balance_error(estimate: np.ndarray, reference: np.ndarray, rows: int) -> float:
    """RMS difference of log luminance of two maps shrunk to `rows` x 2 `rows` (area average) after one global
    scale, texels weighted by solid angle: how far the light's broad balance is from the reference's."""
    weights = np.broadcast_to(texel_solid_angles(rows), (rows, 2 * rows))
    logs = [np.log(np.maximum(luminance(resize_image(m, rows, 2 * rows)), 0.0)
                   + EPS * (robust_level(luminance(m)) or 1.0)) for m in (estimate, reference)]
    diff = logs[0] - logs[1]
    diff = diff - (weights * diff).sum() / weights.sum()
    return float(np.sqrt((weights * diff ** 2).sum() / weights.sum()))


def env_metrics(estimate: np.ndarray, reference: np.ndarray) -> dict[str, float]:
    """PSNR/SSIM of a scale-aligned, tone-mapped env map against the reference (resized to it), and the log error
    of its broad balance at BALANCE_ROWS rows (`env_balance_2`, ...)."""
    a, b, s = aligned_env(estimate, reference)
    return {"env_psnr": psnr(a, b), "env_ssim": ssim(a, b), "env_scale": s,
            **{name: balance_error(estimate, reference, rows) for name, rows in zip(ENV_BALANCE, BALANCE_ROWS)}}


def albedo_mse(estimate: np.ndarray, reference: np.ndarray) -> tuple[float, np.ndarray]:
    """MSE after per-channel least-squares scale alignment; returns (mse, scales)."""
    reference = resize_image(reference, *estimate.shape[:2])
    e, r = estimate.reshape(-1, 3).astype(np.float64), reference.reshape(-1, 3).astype(np.float64)
    scales = (e * r).sum(0) / np.maximum((e * e).sum(0), EPS)
    return float(((e * scales - r) ** 2).mean()), scales


