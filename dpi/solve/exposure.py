"""Exposure: the absolute scale of a capture's radiance, factored out once so nothing depends on it.

The same scene comes as EXRs at any absolute scale (x1e-6 .. x1e6), and inverse rendering cannot
tell a brighter map from a darker one anyway. The solvers' step sizes, clamps and loss magnitudes
work at radiance of order one, so the inverse problem divides every image by the capture's
exposure: the level of its training views' foreground over MIDDLE_GREY. Solving runs in these
normalised units and env maps are multiplied back on output (albedo, roughness and metallic are
scale-free). Metrics compare views in the same units and env maps at their reference's level, so
the same capture scores the same at any exposure.
"""

from __future__ import annotations

import numpy as np
import torch

from dpi.io.images import luminance

MIDDLE_GREY = 0.18
"""the foreground level of a capture in normalised units (photographic middle grey)"""


def robust_level(values: np.ndarray | torch.Tensor) -> float:
    """Median of the positive values (0 when none is positive): a level that black pixels do not pull to 0."""
    values = np.asarray(values, dtype=np.float64).ravel()
    positive = values[values > 0]
    return float(np.median(positive)) if positive.size else 0.0


def middle_grey_gain(values: np.ndarray | torch.Tensor) -> float:
    """The factor that brings the robust level of luminances `values` to MIDDLE_GREY (1 when all are black)."""
    level = robust_level(values)
    return MIDDLE_GREY / level if level > 0 else 1.0


def capture_exposure(images: list[torch.Tensor], masks: list[torch.Tensor], where: str) -> float:
    """Scene radiance per normalised unit: the foreground level of the views (H, W, 3) over MIDDLE_GREY.

    `where` (the capture) starts the error raised when every foreground pixel is black."""
    level = robust_level(np.concatenate([luminance(image[mask]).numpy() for image, mask in zip(images, masks)]))
    if level == 0:
        raise ValueError(f"{where}: every foreground pixel of the training views is black: nothing to fit")
    return level / MIDDLE_GREY
