"""Mask pixels that see the ground: where a mask took ground for the object (a strip under it, a
torus hole it filled), the views agree on that ground under the ground plane's own homography.

**The ground.** When every camera looks from above, the ground is a plane {x . up = height} below
the object. Its height is fitted to the pixels just outside the masks (sure background): the plane
whose induced warp of the neighbour views best matches them (median NCC), searched coarse on half-
size images from two bounding-box diagonals below the object to a quarter diagonal above its lowest
point, then refined at full size. Band pixels whose rays miss the plane, or whose point no neighbour
sees, do not count. A plain ground matches at no height: when fewer than `ground_fit` of the
band pixels reach `GROUND_SEED` under the best plane, nothing is removed.

**The test.** A masked pixel sees the ground when its NCC under that plane reaches `GROUND_SEED`,
or `GROUND_GROW` in a region connected to such a pixel (hysteresis), and beats its best NCC at
any depth inside the carved hull (`OBJECT_PLANES`, ending `CLEARANCE` pixels above the ground):
smooth shading on the object can match a wrong warp, but its own depth matches better. Regions
under `GROUND_MIN_PIXELS` are dropped. Where an NCC window straddles the silhouette, the ground's
half of it matches, so the object's outermost pixels (up to half a window) may go with the ground.
"""

from __future__ import annotations

import numpy as np
import torch

from dpi.capture.cameras import Camera
from dpi.capture.consistency import raycasting_scene
from dpi.preprocess.hull import axes_centre
from dpi.preprocess.morphology import grow
from dpi.preprocess.stereo import Matcher, StereoParams, camera_rays, grey, hull_depth_range, neighbour_views

GROUND_GROW = 0.7
"""NCC at which a masked pixel connected to a seed sees the ground too"""
GROUND_MIN_PIXELS = 20
"""ground regions smaller than this (pixels) stay in the mask"""
GROUND_SEED = 0.95
"""NCC under the ground plane's homography at which a masked pixel sees the ground"""

FIT_VIEWS = 8
"""views the ground's height is fitted on (evenly spread over the capture)"""
COARSE_STEP = 6
"""height step of the coarse search on half-size images, in pixel footprints at the object (the match
peak is about 30 wide there); the fine search covers one coarse step either side in half footprints"""
OBJECT_PLANES = 12
"""depths per pixel over the carved hull that the ground's match must beat"""
CLEARANCE = 3
"""the hull's depths stop this many pixel footprints above the ground (a tie is no evidence)"""
BAND = (3, 20)
"""the fit's background pixels: between these distances (pixels) outside the mask"""


def plane_depths(camera: Camera, up: np.ndarray, heights: np.ndarray) -> np.ndarray:
    """Camera-space depths (P, h, w) at which every pixel's ray meets the planes {x . up = height};
    -1 where it does not (rays that do not go down to a plane below the camera)."""
    rays = camera_rays(camera) @ camera.c2w[:3, :3].T
    slope = (rays @ up)[None]
    offsets = np.asarray(heights, np.float64)[:, None, None] - camera.center @ up
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = offsets / slope
    return np.where((slope < -1e-6) & (depth > 0), depth, -1.0).astype(np.float32)


def plane_scores(matcher: Matcher, camera: Camera, up: np.ndarray, heights: np.ndarray, batch: int = 8) -> np.ndarray:
    """NCC (P, h, w) of a view against its neighbours (a full-frame Matcher) under each plane's
    homography (-1: the ray misses the plane)."""
    out = []
    for start in range(0, len(heights), batch):
        depth = torch.from_numpy(plane_depths(camera, up, heights[start:start + batch]))
        out.append(torch.where(depth > 0, matcher.scores(depth), torch.tensor(-1.0)).numpy())
    return np.concatenate(out)


def range_scores(matcher: Matcher, near: np.ndarray, far: np.ndarray, planes: int, batch: int = 8) -> np.ndarray:
    """Best NCC (h, w) over `planes` depths spread over each pixel's [near, far] (-1 where that is empty)."""
    valid = np.isfinite(near) & np.isfinite(far) & (far > near)
    lo = torch.from_numpy(np.where(valid, near, 1.0).astype(np.float32))
    hi = torch.from_numpy(np.where(valid, far, 1.0).astype(np.float32))
    steps = torch.linspace(0, 1, planes)[:, None, None]
    best = torch.full(lo.shape, -1.0)
    for start in range(0, planes, batch):
        z = lo + (hi - lo) * steps[start:start + batch]
        best = torch.maximum(best, matcher.scores(z).max(0).values)
    return np.where(valid, best.numpy(), -1.0)


def pixel_footprint(cameras: list[Camera]) -> float:
    """The median size of a pixel at the point the cameras look at (world units)."""
    centre = axes_centre(cameras)
    return float(np.median([np.linalg.norm(cam.center - centre) / cam.fx for cam in cameras]))


def view_matcher(greys: list[np.ndarray], cameras: list[Camera], neighbours: list[list[int]], i: int,
                 cfg: StereoParams) -> Matcher:
    """A full-frame Matcher of view i against its neighbours."""
    return Matcher(greys[i], cameras[i], [(greys[j], cameras[j]) for j in neighbours[i]], slice(None), slice(None),
                   cfg)


def background_band(mask: np.ndarray) -> np.ndarray:
    """Pixels between BAND[0] and BAND[1] pixels outside a mask: background near the object."""
    return grow(mask, BAND[1]) & ~grow(mask, BAND[0])


def _half(image: np.ndarray, camera: Camera) -> tuple[np.ndarray, Camera]:
    """An image area-downsampled to half size and its camera."""
    import cv2

    h, w = image.shape[:2]
    small = cv2.resize(image.astype(np.float32), (w // 2, h // 2), interpolation=cv2.INTER_AREA)
    return small, camera.resized(w // 2, h // 2)


def band_scores(greys: list[np.ndarray], cameras: list[Camera], bands: list[np.ndarray],
                neighbours: list[list[int]], views: list[int], up: np.ndarray, heights: np.ndarray,
                cfg: StereoParams) -> np.ndarray:
    """NCC (P, N) of the given views' N band pixels under each plane, NaN where there is none (a ray
    that misses the plane, or a point no neighbour sees)."""
    scores = np.concatenate([plane_scores(view_matcher(greys, cameras, neighbours, i, cfg), cameras[i], up,
                                          heights)[:, bands[i]] for i in views], axis=1)
    return np.where(scores > -1, scores, np.nan)


def _medians(scores: np.ndarray) -> np.ndarray:
    """Median of each row over its finite entries (-1 for a row without any)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nan_to_num(np.nanmedian(scores, axis=1), nan=-1.0)


def fit_ground(greys: list[np.ndarray], cameras: list[Camera], masks: list[np.ndarray], neighbours: list[list[int]],
               up: np.ndarray, lowest: float, diagonal: float, cfg: StereoParams) -> tuple[float, float]:
    """(height, match) of the ground plane best matching the background near the object (highest median
    NCC), whose lowest carved point is at height `lowest` and whose box has the given diagonal; match:
    the fraction of those background pixels that reach `GROUND_SEED` under it."""
    views = list(range(0, len(cameras), max(len(cameras) // FIT_VIEWS, 1)))
    bands = [background_band(m) for m in masks]
    pixel = pixel_footprint(cameras)
    half = [_half(g, c) for g, c in zip(greys, cameras)]
    half_bands = [b[::2, ::2][:h.shape[0], :h.shape[1]] for b, (h, _) in zip(bands, half)]
    coarse = np.arange(lowest - 2 * diagonal, lowest + 0.25 * diagonal, COARSE_STEP * pixel)
    scores = band_scores([h for h, _ in half], [c for _, c in half], half_bands, neighbours, views, up, coarse, cfg)
    best = float(coarse[int(np.argmax(_medians(scores)))])
    fine = best + np.arange(-COARSE_STEP, COARSE_STEP + 0.01, 0.5) * pixel
    scores = band_scores(greys, cameras, bands, neighbours, views, up, fine, cfg)
    k = int(np.argmax(_medians(scores)))
    seen = np.isfinite(scores[k])
    return float(fine[k]), float((scores[k][seen] >= GROUND_SEED).mean()) if seen.any() else 0.0


def ground_pixels(greys: list[np.ndarray], cameras: list[Camera], masks: list[np.ndarray],
                  neighbours: list[list[int]], up: np.ndarray, height: float, hull: tuple[np.ndarray, np.ndarray],
                  cfg: StereoParams) -> list[np.ndarray]:
    """Per view, the masked pixels that see the ground plane at `height`: they match under its
    homography (hysteresis) better than at any depth inside the carved hull (vertices, faces) above it."""
    import cv2
    from skimage.filters import apply_hysteresis_threshold

    scene = raycasting_scene(*hull)
    clearance = CLEARANCE * pixel_footprint(cameras)
    out = []
    for i, (cam, mask) in enumerate(zip(cameras, masks)):
        matcher = view_matcher(greys, cameras, neighbours, i, cfg)
        on_plane = plane_scores(matcher, cam, up, np.array([height]))[0]
        plane_depth = plane_depths(cam, up, np.array([height]))[0]
        near, far = hull_depth_range(scene, cam, 2 * float(np.linalg.norm(hull[0] - cam.center, axis=1).max()))
        far = np.where(plane_depth > 0, np.minimum(far, plane_depth - clearance), far)
        candidate = mask & (on_plane > range_scores(matcher, near, far, OBJECT_PLANES))
        ground = apply_hysteresis_threshold(np.where(candidate, on_plane, -1.0), GROUND_GROW, GROUND_SEED)
        count, labels, stats, _ = cv2.connectedComponentsWithStats(ground.astype(np.uint8), connectivity=8)
        big = [k for k in range(1, count) if stats[k, cv2.CC_STAT_AREA] >= GROUND_MIN_PIXELS]
        out.append(np.isin(labels, big))
    return out


def remove_ground(cameras: list[Camera], masks: list[np.ndarray], images: list[np.ndarray], up: np.ndarray,
                  hull: tuple[np.ndarray, np.ndarray], cfg: StereoParams) -> tuple[list[np.ndarray], dict]:
    """The masks without the pixels that see the ground (unchanged when the ground matches nowhere),
    and a summary: the ground's height, its match (`fit_ground`), the fraction of mask pixels removed. `hull`:
    (vertices, faces) of the closed carved hull the masks give."""
    greys = [grey(image, cfg.blur_px) for image in images]
    neighbours = neighbour_views(cameras, axes_centre(cameras), cfg.neighbours, cfg.max_baseline_deg)
    lowest = float((hull[0] @ up).min())
    diagonal = float(np.linalg.norm(hull[0].max(0) - hull[0].min(0)))
    height, match = fit_ground(greys, cameras, masks, neighbours, up, lowest, diagonal, cfg)
    summary = {"height": round(height, 5), "match": round(match, 4), "removed_fraction": 0.0}
    if match < cfg.ground_fit:
        return masks, summary
    ground = ground_pixels(greys, cameras, masks, neighbours, up, height, hull, cfg)
    removed = sum(int(g.sum()) for g in ground) / max(sum(int(m.sum()) for m in masks), 1)
    summary["removed_fraction"] = round(removed, 5)
    return [m & ~g for m, g in zip(masks, ground)], summary
