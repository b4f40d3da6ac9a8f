"""Growing and shrinking boolean masks by a disc: what the masks, their witnesses and the ground test share."""

from __future__ import annotations

import numpy as np


def grow(mask: np.ndarray, pixels: int) -> np.ndarray:
    """Dilate a boolean mask by a disc of radius `pixels` (0: the mask as it is)."""
    import cv2

    if pixels <= 0:
        return mask.astype(bool)
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * pixels + 1, 2 * pixels + 1))
    return cv2.dilate(mask.astype(np.uint8), disc) > 0


def shrink(mask: np.ndarray, pixels: int) -> np.ndarray:
    """Erode a boolean mask by a disc of radius `pixels`."""
    return ~grow(~mask, pixels)
