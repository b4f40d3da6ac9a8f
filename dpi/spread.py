"""How much posterior samples differ: scale-free maps compared across samples (sigma2_sample).

Illumination is known only up to a global scale, so maps are compared after dividing by their median
luminance and tone mapping; the variance across samples, per element and averaged, is the paper's
sigma2_sample. Used by the summary, the adaptive stop rule and the studies alike.
"""

from __future__ import annotations

import numpy as np

from dpi.exposure import robust_level
from dpi.images import luminance, tonemap


def normalized_env(env: np.ndarray) -> np.ndarray:
    """Env map divided by its median (positive) luminance, tone-mapped: scale-free, for spread across samples."""
    return tonemap(env / (robust_level(luminance(env)) or 1.0))


def sample_variance(samples: list[np.ndarray]) -> float:
    """Per-element variance across samples, averaged (sigma2_sample); 0 for a single sample."""
    if len(samples) < 2:
        return 0.0
    return float(np.stack(samples).var(axis=0, ddof=1).mean())
