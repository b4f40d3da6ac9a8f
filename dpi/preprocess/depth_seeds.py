"""Which pixels the views' parallax puts on the object and which behind it: seeds for the masks on a busy background.

Colour cannot tell a bronze statue from the facade behind it; parallax can. The object lies inside a sphere around
the point the cameras look at (its sparse points' extent), the background metres behind it. For each view the
nearest views (dpi.preprocess.stereo.neighbour_views) are warped onto depths inside that sphere along each pixel's
ray and onto depths behind it (uniform in inverse depth, out to infinity), and the zero-mean NCC of the best
neighbours scores each (dpi.preprocess.stereo.Matcher). A pixel whose best match inside the sphere beats its best
match behind it by `MARGIN`, at a score of at least `MIN_SCORE`, is an object seed; the reverse, or a pixel whose
ray misses the sphere, a background seed; the rest (no texture, or no clear winner) is left to the segmentation.
"""

from __future__ import annotations

import numpy as np
import torch

from dpi.capture.cameras import Camera
from dpi.preprocess.stereo import Matcher, StereoParams, camera_rays, neighbour_views

OBJECT_DEPTHS = 24
"""depths per pixel inside the object's sphere"""
BACKGROUND_DEPTHS = 24
"""depths per pixel behind the sphere, uniform in inverse depth from its far side to 100 times as far"""
MIN_SCORE = 0.5
"""NCC a seed's winning depth must reach (a textured match, not noise)"""
MARGIN = 0.1
"""NCC by which the winning range must beat the other"""
NEIGHBOURS = 4
"""views each view is matched against"""
PARAMS = StereoParams(window=9, blur_px=1.0)
"""the matcher's window and blur (the geometry stage's stereo, with a smaller window: seeds, not depths)"""
OBJECT, UNKNOWN, BACKGROUND = 1, 0, -1


def sphere_depths(camera: Camera, centre: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Camera-space depths (h, w) where each pixel's ray enters and leaves the sphere; NaN where it misses."""
    rays = camera_rays(camera)  # camera space, z = -1
    world = rays @ camera.c2w[:3, :3].T
    offset = camera.center - centre
    a = (world * world).sum(-1)
    b = 2 * (world @ offset)
    c = float(offset @ offset - radius * radius)
    disc = b * b - 4 * a * c
    root = np.sqrt(np.where(disc >= 0, disc, np.nan))
    near, far = (-b - root) / (2 * a), (-b + root) / (2 * a)
    return np.where(far > 0, np.maximum(near, 1e-3), np.nan), np.where(far > 0, far, np.nan)


def view_seeds(grey: np.ndarray, camera: Camera, others: list[tuple[np.ndarray, Camera]], centre: np.ndarray,
               radius: float, batch: int = 8) -> np.ndarray:
    """(h, w) int8 seeds of one view (OBJECT, BACKGROUND or UNKNOWN; module notes), from its grey image and its
    neighbours' (grey image, camera)."""
    near, far = sphere_depths(camera, centre, radius)
    hit = np.isfinite(near)
    seeds = np.full(grey.shape, BACKGROUND, np.int8)
    if not hit.any() or not others:
        return seeds
    matcher = Matcher(grey, camera, others, slice(None), slice(None), PARAMS)
    back = float(np.nanmax(far))
    near_t = torch.from_numpy(np.where(hit, near, back).astype(np.float32))
    far_t = torch.from_numpy(np.where(hit, far, back).astype(np.float32))
    steps = torch.linspace(0, 1, OBJECT_DEPTHS)[:, None, None]
    inside = near_t + steps * (far_t - near_t)
    inverse = torch.linspace(1.0, 0.01, BACKGROUND_DEPTHS)[:, None, None] / far_t
    behind = 1.0 / inverse

    def best(z: torch.Tensor) -> torch.Tensor:
        return torch.cat([matcher.scores(z[i:i + batch]) for i in range(0, len(z), batch)]).amax(0)

    with torch.no_grad():
        s_in, s_behind = best(inside).numpy(), best(behind).numpy()
    seeds[hit] = UNKNOWN
    seeds[hit & (s_in >= MIN_SCORE) & (s_in >= s_behind + MARGIN)] = OBJECT
    seeds[hit & (s_behind >= MIN_SCORE) & (s_behind >= s_in + MARGIN)] = BACKGROUND
    return seeds


def depth_seeds(greys: list[np.ndarray], cameras: list[Camera], centre: np.ndarray, radius: float) -> list[np.ndarray]:
    """Each view's seeds (view_seeds) against its NEIGHBOURS nearest views."""
    neighbours = neighbour_views(cameras, centre, NEIGHBOURS, PARAMS.max_baseline_deg)
    return [view_seeds(greys[i], cameras[i], [(greys[j], cameras[j]) for j in neighbours[i]], centre, radius)
            for i in range(len(cameras))]
