"""Foreground masks from photos and cameras, without a learned model.

Two classical methods, chosen per image:
- **colour keying** when the background is uniform (the image border has one colour, as in a
  studio or turntable capture): foreground is every pixel whose colour differs from the key;
- **GrabCut** otherwise, seeded by a soft prior: the object's sparse 3-D points (from
  structure from motion) are projected into the view, and the convex hull of their projections,
  grown by a margin, is *probably foreground*; a band around it is *probably background*, and
  only what lies far outside is *background* for sure. No single point is a hard seed, so a few
  stray points cannot force a wrong region into the mask. Without (enough) sparse points on the
  object (given cameras, a textureless object) the first prior is the projection of the sphere
  the cameras look at. A second pass then starts from the *consensus*: the visual hull the
  first masks agree on (a voxel is carved when several views see it outside, so single failures
  do not matter), projected into each view; where GrabCut still disagrees with it, the
  projected hull is the mask.

Either way the largest connected component is kept and small holes are filled; holes larger
than `fill_holes_below` of the object (the hole of a torus) are kept.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dpi.cameras import Camera
from dpi.images import read_image, to_uint8, write_mask

log = logging.getLogger(__name__)

METHODS = ("auto", "grabcut", "key")


@dataclass
class MaskConfig:
    """Settings of mask extraction."""

    method: str = "auto"
    """auto (keying on a uniform background, else GrabCut) | grabcut | key"""
    hull_margin: float = 0.05
    """growth of the projected points' hull that is probably foreground, as a fraction of its size"""
    hull_core: float = 0.12
    """the hull shrunk by this fraction of its size is foreground for sure (a region, never single points; 0: off)"""
    background_margin: float = 0.35
    """beyond this growth of the hull (fraction of its size) pixels are background for sure"""
    grabcut_iterations: int = 4
    key_max_spread: float = 0.06
    """the background is uniform when the border's colours (sRGB, 0-1) spread less than this"""
    key_threshold: float = 0.1
    """keying: a pixel is foreground when its sRGB colour is farther than this from the key colour"""
    fill_holes_below: float = 0.01
    """holes smaller than this fraction of the mask's area are filled"""
    min_points: int = 30
    """fewer object points than this: the consensus prior (sphere, then the carved hull of a first pass)"""
    consensus: bool = True
    """refine with a second GrabCut pass from the visual hull the first pass's masks agree on"""
    consensus_votes: int = 3
    """views that must agree to carve a voxel from the first-pass hull"""


def border_colour(image8: np.ndarray, width: float = 0.04) -> tuple[np.ndarray, float]:
    """Median colour (3,) of the image border (a `width` fraction of each side) and its spread:
    the 90th percentile of the border pixels' distance to that colour, in [0, 1] sRGB units."""
    h, w = image8.shape[:2]
    b = max(1, int(round(width * min(h, w))))
    border = np.concatenate([image8[:b].reshape(-1, 3), image8[-b:].reshape(-1, 3),
                             image8[:, :b].reshape(-1, 3), image8[:, -b:].reshape(-1, 3)]).astype(np.float64) / 255
    colour = np.median(border, axis=0)
    return colour, float(np.percentile(np.linalg.norm(border - colour, axis=1), 90))


def key_mask(image8: np.ndarray, colour: np.ndarray, threshold: float) -> np.ndarray:
    """Pixels whose sRGB colour is farther than `threshold` from the key colour."""
    return np.linalg.norm(image8.astype(np.float64) / 255 - colour, axis=-1) > threshold


def _grow(mask: np.ndarray, pixels: int) -> np.ndarray:
    """Dilate a boolean mask by a disc of radius `pixels`."""
    import cv2

    if pixels <= 0:
        return mask
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * pixels + 1, 2 * pixels + 1))
    return cv2.dilate(mask.astype(np.uint8), disc) > 0


def hull_prior(points_xy: np.ndarray, shape: tuple[int, int], cfg: MaskConfig) -> np.ndarray:
    """GrabCut label image (h, w) from projected points: the grown convex hull probably foreground,
    a band around it probably background, the rest background."""
    import cv2

    h, w = shape
    hull = cv2.convexHull(np.round(points_xy).astype(np.int32).reshape(-1, 1, 2))
    inside = np.zeros(shape, np.uint8)
    cv2.fillConvexPoly(inside, hull, 1)
    labels = _prior_from_region(inside > 0, cfg)
    if cfg.hull_core > 0:  # the core of the hull, well inside the object's points, is foreground for sure
        size = max(np.sqrt(inside.sum()), 1.0)
        r = int(round(cfg.hull_core * size))
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
        labels[cv2.erode(inside, disc) > 0] = cv2.GC_FGD
    return labels


def _prior_from_region(region: np.ndarray, cfg: MaskConfig) -> np.ndarray:
    """GrabCut labels around a region that roughly covers the object (the object is inside the
    image, so a thin strip along the border is background too)."""
    import cv2

    size = max(np.sqrt(region.sum()), 1.0)
    labels = np.full(region.shape, cv2.GC_BGD, np.uint8)
    labels[_grow(region, int(round(cfg.background_margin * size)))] = cv2.GC_PR_BGD
    labels[_grow(region, int(round(cfg.hull_margin * size)))] = cv2.GC_PR_FGD
    _border_background(labels)
    return labels


def _border_background(labels: np.ndarray, border: float = 0.03) -> None:
    """Mark a strip along the image border (a `border` fraction of the shorter side) as background."""
    import cv2

    b = max(1, int(round(border * min(labels.shape))))
    for strip in (labels[:b], labels[-b:], labels[:, :b], labels[:, -b:]):
        strip[...] = cv2.GC_BGD


def sphere_prior(camera: Camera, centre: np.ndarray, radius: float, cfg: MaskConfig,
                 border: float = 0.03) -> np.ndarray:
    """Loose GrabCut labels from a sphere: its projected disc probably foreground, the rest probably
    background, and a thin strip along the image border background for sure."""
    import cv2

    xy, depth = camera.project(np.asarray(centre, dtype=np.float64)[None])
    r = camera.fx * radius / max(float(depth[0]), 1e-9)
    yy, xx = np.mgrid[: camera.height, : camera.width]
    disc = (xx + 0.5 - xy[0, 0]) ** 2 + (yy + 0.5 - xy[0, 1]) ** 2 <= r * r
    labels = np.where(disc, cv2.GC_PR_FGD, cv2.GC_PR_BGD).astype(np.uint8)
    _border_background(labels, border)
    return labels


def grabcut(image8: np.ndarray, labels: np.ndarray, iterations: int) -> np.ndarray:
    """Boolean foreground of GrabCut started from a label image."""
    import cv2

    labels = labels.copy()
    if not (labels == cv2.GC_PR_FGD).any() or not np.isin(labels, (cv2.GC_BGD, cv2.GC_PR_BGD)).any():
        return labels == cv2.GC_PR_FGD
    bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    cv2.setRNGSeed(0)
    cv2.grabCut(np.ascontiguousarray(image8[..., ::-1]), labels, None, bgd, fgd, iterations, cv2.GC_INIT_WITH_MASK)
    return np.isin(labels, (cv2.GC_FGD, cv2.GC_PR_FGD))


def clean_mask(mask: np.ndarray, fill_holes_below: float) -> np.ndarray:
    """Largest connected component, with holes smaller than `fill_holes_below` of its area filled."""
    import cv2

    count, comp, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    if count <= 1:
        return mask.astype(bool)
    largest = comp == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    count, holes, stats, _ = cv2.connectedComponentsWithStats((~largest).astype(np.uint8), connectivity=4)
    out = largest.copy()
    border = set(np.unique(np.concatenate([holes[0], holes[-1], holes[:, 0], holes[:, -1]])).tolist())
    for label in range(1, count):
        if label not in border and stats[label, cv2.CC_STAT_AREA] < fill_holes_below * largest.sum():
            out[holes == label] = True
    return out


def object_mask(image: np.ndarray, camera: Camera, cfg: MaskConfig, points: np.ndarray | None = None,
                sphere: tuple[np.ndarray, float] | None = None,
                labels: np.ndarray | None = None) -> tuple[np.ndarray, str]:
    """Foreground mask (h, w) of one linear RGB image, and the method used ("key" or "grabcut").

    The GrabCut prior is `labels` when given, else the hull of the object's sparse points (N, 3)
    projected by the camera, else the projection of `sphere` (centre, radius).
    """
    image8 = to_uint8(image)
    colour, spread = border_colour(image8)
    method = cfg.method
    if method == "auto":
        method = "key" if spread < cfg.key_max_spread else "grabcut"
    if method == "key":
        mask = key_mask(image8, colour, max(cfg.key_threshold, 2 * spread))
    else:
        xy = np.zeros((0, 2))
        if labels is None and points is not None and len(points):
            xy, depth = camera.project(points)
            inside = (depth > 0) & (xy[:, 0] >= 0) & (xy[:, 0] < camera.width) & (xy[:, 1] >= 0) & (xy[:, 1] < camera.height)
            xy = xy[inside]
        if labels is not None:
            pass
        elif len(xy) >= min(cfg.min_points, 8):
            labels = hull_prior(xy, image.shape[:2], cfg)
        elif sphere is not None:
            labels = sphere_prior(camera, sphere[0], sphere[1], cfg)
        else:
            raise ValueError(f"view {camera.name!r}: no object points and no sphere prior for GrabCut")
        mask = grabcut(image8, labels, cfg.grabcut_iterations)
    return clean_mask(mask, cfg.fill_holes_below), method


def region_prior(camera: Camera, voxels: np.ndarray, voxel_size: float, cfg: MaskConfig) -> np.ndarray:
    """GrabCut labels from the projection of occupied voxel centres (N, 3) of a hull into a view."""
    xy, depth = camera.project(voxels)
    keep = (depth > 0) & (xy[:, 0] >= 0) & (xy[:, 0] < camera.width) & (xy[:, 1] >= 0) & (xy[:, 1] < camera.height)
    region = np.zeros((camera.height, camera.width), bool)
    region[xy[keep, 1].astype(int), xy[keep, 0].astype(int)] = True
    radius = int(np.ceil(camera.fx * voxel_size / max(float(np.median(depth[keep])), 1e-9))) if keep.any() else 0
    region = _grow(region, radius)
    labels = _prior_from_region(region, cfg)
    if cfg.hull_core > 0:  # deep inside the views' consensus: foreground for sure
        import cv2

        r = int(round(cfg.hull_core * max(np.sqrt(region.sum()), 1.0)))
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
        labels[cv2.erode(region.astype(np.uint8), disc) > 0] = cv2.GC_FGD
    return labels


def consensus_hull(cameras: list[Camera], masks: list[np.ndarray], votes: int,
                   resolution: int = 64) -> tuple[np.ndarray, float]:
    """Centres (N, 3) of the voxels inside the hull that first-pass masks agree on, and the voxel size."""
    from dpi.preprocess.geometry import carve, grid_points, search_box, signed_distance_2d

    lo, hi = search_box(cameras)
    field, origin, size = carve(cameras, [signed_distance_2d(m) for m in masks], lo, hi, resolution, votes)
    inside = np.argwhere(field < 0)
    return origin + inside * size, size


def derive_masks(images: dict[str, Path], cameras: dict[str, Camera], out_dir: str | Path,
                 cfg: MaskConfig | None = None, points: np.ndarray | None = None) -> dict:
    """Write one mask PNG per view (out_dir/{view}.png) and return a summary (prior, method per view, areas).

    Views without a camera get no mask. With fewer than `min_points` object points the GrabCut
    prior is the consensus hull of a first pass (see the module notes).
    """
    cfg = cfg or MaskConfig()
    if cfg.method not in METHODS:
        raise ValueError(f"mask method must be one of {', '.join(METHODS)}, got {cfg.method!r}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    names = [n for n in images if n in cameras]
    pictures = {n: read_image(images[n]) for n in names}
    use_points = points is not None and len(points) >= cfg.min_points
    priors = {}
    if cfg.consensus and cfg.method != "key":
        centre, radius = visible_sphere([cameras[n] for n in names])
        sphere = (centre, 0.7 * radius)
        first = {n: object_mask(pictures[n], cameras[n], cfg, points if use_points else None, sphere)[0]
                 for n in names}
        votes = min(cfg.consensus_votes, max(1, len(names) // 4))
        voxels, size = consensus_hull([cameras[n] for n in names], [first[n] for n in names], votes)
        if len(voxels):
            priors = {n: region_prior(cameras[n], voxels, size, cfg) for n in names}
        else:
            log.warning("first-pass masks agree on no hull; keeping them")
            priors = {n: None for n in names}
    first_prior = "sparse points" if use_points else "sphere"
    summary = {"views": {}, "prior": f"{first_prior}, then consensus hull" if priors else first_prior}
    for name in names:
        if name in priors and priors[name] is None:
            mask, method = first[name], "grabcut"
        else:
            mask, method = object_mask(pictures[name], cameras[name], cfg, points if use_points else None,
                                       sphere_or_none(priors, cameras, names), labels=priors.get(name))
            if priors.get(name) is not None:
                hull = np.isin(priors[name], (cv2_labels().GC_FGD, cv2_labels().GC_PR_FGD))
                if mask_overlap(mask, hull) < 0.5:  # GrabCut lost the object: keep the views' consensus
                    log.warning("%s: GrabCut disagrees with the consensus hull; using the hull's projection", name)
                    mask, method = clean_mask(hull, cfg.fill_holes_below), "consensus hull"
        if not mask.any():
            raise ValueError(f"{images[name]}: empty foreground mask ({method}); check the capture or the mask settings")
        write_mask(out_dir / f"{name}.png", mask)
        summary["views"][name] = {"method": method, "foreground_fraction": round(float(mask.mean()), 4)}
    return summary


def sphere_or_none(priors: dict, cameras: dict[str, Camera], names: list[str]):
    """The loose sphere prior for views without a consensus prior (only when no points are given)."""
    if priors:
        return None
    centre, radius = visible_sphere([cameras[n] for n in names])
    return centre, 0.7 * radius


def cv2_labels():
    """The cv2 module (GrabCut label constants), imported lazily."""
    import cv2

    return cv2


def mask_overlap(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two boolean masks."""
    union = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / union) if union else 1.0


def visible_sphere(cameras: list[Camera]) -> tuple[np.ndarray, float]:
    """(centre, radius): the point the cameras look at and 90% of the largest sphere around it that
    lies inside every camera's field of view."""
    from dpi.preprocess.sfm import axes_centre

    centre = axes_centre(cameras)
    radius = np.inf
    for cam in cameras:
        distance = np.linalg.norm(cam.center - centre)
        half = np.arctan(min(cam.width / (2 * cam.fx), cam.height / (2 * cam.fy)))
        radius = min(radius, distance * np.sin(half))
    return centre, 0.9 * float(radius)
