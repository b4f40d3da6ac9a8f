"""How far each derived mask can be trusted, from three witnesses that do not share its mistakes.

- **Points** (absolute): a silhouette holds the projection of every point of the object, seen or hidden, so the
  object's sparse points (from structure from motion) that fall outside a view's mask are parts of the object the
  mask cut off (a head cut off at the ears). `point_coverage` is the share of the points in the frame that fall
  inside the mask, grown by a pixel or two for the points' own error.
- **Edges** (absolute): an object's outline is where the image changes; a mask that cuts through the object or
  through the background runs across smooth fur or wallpaper. `edge_support` is the share of the mask's outline
  within a few pixels of an image edge (Canny).
- **The frame** (absolute): the object is whole in every photo (the capture's one assumption), so a mask that reaches
  the frame's edge holds something the frame cuts: the stand the object sits on, the ground, the background, or the
  object is not whole in that photo. `frame_contact` counts the mask's pixels on the frame's edge.
- **Other views** (relative): the mask's IoU with the projection of the hull the masks carve together
  (`agreement`, dpi.preprocess.masks.mask_agreement), against the median view's. The majority may be wrong the
  same way (every view missing the same part), which is why the absolute witnesses come first.

A view is unreliable when any witness fails (`verdict`): the masks' summary, the log and the report name it and why.
A capture whose masks are mostly unreliable stops before the geometry is carved (`check_usable`).
"""

from __future__ import annotations

import numpy as np

from dpi.capture.cameras import Camera
from dpi.preprocess.morphology import grow

MASK_AGREEMENT = 0.85
"""a mask is reliable when its IoU with the projection of the hull the masks carve together reaches this share
of the median view's"""
AGREEMENT_VOTE_SHARE = 0.25
"""share of the views that must see a voxel outside their masks to carve it, for the agreement's hull"""
POINT_COVERAGE_MIN = 0.9
"""a mask is unreliable when fewer of the object's points in the frame fall inside it than this share"""
POINT_TOLERANCE = 0.02
"""the mask is grown by this fraction of its size (at least a pixel) before the points are counted: their error"""
MIN_POINTS_IN_VIEW = 20
"""with fewer of the object's points in the frame, the points witness nothing"""
EDGE_SUPPORT_MIN = 0.5
"""a mask is unreliable when less of its outline than this share lies near an image edge"""
EDGE_RADIUS = 0.02
"""an outline pixel is near an edge within this fraction of the mask's size (at least 2 pixels)"""
MOSTLY_UNRELIABLE = 0.5
"""a capture stops before the geometry when more than this share of its derived masks is unreliable"""


def _size(mask: np.ndarray) -> float:
    """A mask's size in pixels: the side of the square of its area."""
    return max(float(np.sqrt(mask.sum())), 1.0)


def point_coverage(camera: Camera, mask: np.ndarray, points: np.ndarray | None) -> float | None:
    """Share of the object's points (N, 3) in front of the camera and inside the frame that fall inside the mask
    (h, w), grown by POINT_TOLERANCE; None with fewer than MIN_POINTS_IN_VIEW such points."""
    if points is None or len(points) == 0:
        return None
    xy, depth = camera.project(np.asarray(points, np.float64))
    h, w = mask.shape
    col, row = np.floor(xy[:, 0]).astype(np.int64), np.floor(xy[:, 1]).astype(np.int64)
    inside = (depth > 0) & (col >= 0) & (col < w) & (row >= 0) & (row < h)
    if inside.sum() < MIN_POINTS_IN_VIEW:
        return None
    grown = grow(mask, max(1, int(round(POINT_TOLERANCE * _size(mask)))))
    return float(grown[row[inside], col[inside]].mean())


def image_edges(image8: np.ndarray) -> np.ndarray:
    """Canny edges (h, w) of an 8-bit sRGB image (h, w, 3), on all three channels (a red object on a green wall of
    the same brightness has an edge), lightly blurred so noise is not an edge; the thresholds follow the image's
    median gradient (as much texture as the photo has)."""
    import cv2

    image = cv2.GaussianBlur(np.ascontiguousarray(image8), (3, 3), 0)
    grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    low = max(float(np.median(np.hypot(cv2.Sobel(grey, cv2.CV_32F, 1, 0), cv2.Sobel(grey, cv2.CV_32F, 0, 1)))), 8.0)
    return cv2.Canny(image, low, 2 * low, L2gradient=True) > 0


def frame_contact(mask: np.ndarray) -> int:
    """How many of the mask's (h, w) pixels lie on the frame's edge (its outer rows and columns)."""
    return int(mask[[0, -1], :].sum() + mask[1:-1, [0, -1]].sum())


def edge_support(image8: np.ndarray, mask: np.ndarray) -> float | None:
    """Share of the mask's (h, w) outline within EDGE_RADIUS of an edge of the image (h, w, 3 uint8); the outline
    along the image border is left out (the frame cut it there). None for an empty mask or outline."""
    if not mask.any():
        return None
    outline = mask & grow(~mask, 1)
    outline[[0, -1], :] = outline[:, [0, -1]] = False
    if not outline.any():
        return None
    near = grow(image_edges(image8), max(2, int(round(EDGE_RADIUS * _size(mask)))))
    return float(near[outline].mean())


def verdict(view: dict, agreement_floor: float | None) -> list[str]:
    """Why a view's mask (its summary: method, agreement, point_coverage, frame_contact, edge_support) is
    unreliable: one short reason per failed witness, none when it is reliable."""
    reasons = []
    if view.get("method") == "consensus hull":
        reasons.append("segmentation lost the object (the hull's projection stands in)")
    if view.get("point_coverage") is not None and view["point_coverage"] < POINT_COVERAGE_MIN:
        reasons.append(f"{1 - view['point_coverage']:.0%} of the object's points fall outside")
    if view.get("frame_contact"):
        reasons.append(f"it reaches the frame's edge ({view['frame_contact']} px): it holds what the frame cuts (a "
                       "stand, the ground, the background), or the object is not whole in this photo")
    if view.get("edge_support") is not None and view["edge_support"] < EDGE_SUPPORT_MIN:
        reasons.append(f"{1 - view['edge_support']:.0%} of its outline is on no image edge")
    if agreement_floor is not None and view.get("agreement") is not None and view["agreement"] < agreement_floor:
        reasons.append("disagrees with the other views' masks")
    return reasons


def check_usable(summary: dict, source: str) -> None:
    """Stop with one line when more than MOSTLY_UNRELIABLE of the derived masks in `summary` (the masks stage's,
    read from `source`) are unreliable: the views, and what to do."""
    views, bad = summary.get("views", {}), summary.get("unreliable", [])
    if views and len(bad) > MOSTLY_UNRELIABLE * len(views):
        shown = ", ".join(bad[:8]) + (f" and {len(bad) - 8} more" if len(bad) > 8 else "")
        raise ValueError(f"{source}: the derived masks of {len(bad)} of {len(views)} views are unreliable ({shown}); "
                         "look at them in the report's mask gallery, then bring masks (a masks/ folder or mask_path "
                         "in scene.yaml) or a segmenter's weights (preprocess.masks.weights)")
