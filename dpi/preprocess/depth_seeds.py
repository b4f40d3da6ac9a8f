"""Which pixels the views' parallax puts on the object and which behind it: seeds for the masks on a busy background.

Colour cannot tell a bronze statue from the facade behind it; parallax can. The object is whole in every frame, so it
lies in the space every camera sees (the intersection of their fields of view, a convex region around the point
they look at), the background metres behind it. For each view the nearest views (dpi.preprocess.stereo.
neighbour_views) are warped onto depths inside that region along each pixel's ray and onto depths behind it (both
uniform in inverse depth, `STEP_PX` apart; behind it out to infinity), and the zero-mean NCC of the best neighbour
scores each (dpi.preprocess.stereo.Matcher; the background beside a frame's edge leaves some neighbours' frames as
they turn round the object). A pixel whose best match inside beats its best match behind by `MARGIN`, at a score of
at least `MIN_SCORE`, is an object seed; the reverse, or a pixel whose ray misses the region, a background seed; the
rest (no texture, or no clear winner) is left to the segmentation. The table, plinth or ground the object stands on
lies in that region too, but reaches out of some frames where the object does not: the level plane that best parts
the sparse points every camera sees (above) from the others (below) under and around the object (`support_height`)
cuts it off, and what matches at or below it is background.
"""

from __future__ import annotations

import numpy as np
import torch

from dpi.capture.cameras import Camera
from dpi.preprocess.hull import visible_sphere
from dpi.preprocess.sfm import in_view_fraction, up_direction
from dpi.preprocess.stereo import Matcher, StereoParams, camera_rays, neighbour_views

STEP_PX = 1.5
"""depths per pixel are spaced so that a step moves a point by at most this many pixels in the farthest
neighbour (uniform in inverse depth: inside the space every camera sees, and behind it out to infinity)"""
MIN_SCORE = 0.5
"""NCC a seed's winning depth must reach (a textured match, not noise)"""
MARGIN = 0.1
"""NCC by which the winning range must beat the other"""
NEIGHBOURS = 3
"""views each view is matched against"""
PARAMS = StereoParams(window=9, blur_px=1.0)
"""the matcher's window and blur (the geometry stage's stereo, with a smaller window: seeds, not depths)"""
OBJECT, UNKNOWN, BACKGROUND = 1, 0, -1


def frustum_planes(camera: Camera, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """(normals (4, 3), offsets (4,)) of the half-spaces n . x <= c whose intersection is the camera's field of view,
    widened by `margin` of the image's size on each side."""
    w, h = camera.width * (1 + 2 * margin), camera.height * (1 + 2 * margin)
    x0, x1 = (camera.width - w) / 2, (camera.width + w) / 2
    y0, y1 = (camera.height - h) / 2, (camera.height + h) / 2
    corners = np.array([[(x - camera.cx) / camera.fx, -(y - camera.cy) / camera.fy, -1.0]
                        for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))]) @ camera.c2w[:3, :3].T
    normals = np.array([np.cross(corners[k], corners[(k + 1) % 4]) for k in range(4)])
    axis = -camera.c2w[:3, 2]
    normals *= -np.sign(normals @ axis)[:, None]  # pointing out of the field of view
    return normals, normals @ camera.center


def common_view_depths(camera: Camera, cameras: list[Camera], margin: float) -> tuple[np.ndarray, np.ndarray]:
    """Camera-space depths (h, w) where each pixel's ray enters and leaves the space every camera of `cameras` sees
    (the intersection of their fields of view, a convex region; each widened by `margin`), NaN where it misses."""
    rays = camera_rays(camera).reshape(-1, 3) @ camera.c2w[:3, :3].T  # world directions at camera depth 1
    near, far = np.full(len(rays), 1e-3), np.full(len(rays), np.inf)
    for other in cameras:
        normals, offsets = frustum_planes(other, margin)
        rate = rays @ normals.T  # (P, 4): d(n . x)/dz along each ray
        start = (normals @ camera.center - offsets)[None]  # n . origin - c, <= 0 inside
        with np.errstate(divide="ignore", invalid="ignore"):
            cross = -start / rate
        near = np.maximum(near, np.where(rate < 0, cross, -np.inf).max(1))
        far = np.minimum(far, np.where(rate > 0, cross, np.inf).min(1))
        blocked = ((rate == 0) & (start > 0)).any(1)
        far[blocked] = -np.inf
    hit = far > near
    shape = (camera.height, camera.width)
    return np.where(hit, near, np.nan).reshape(shape), np.where(hit, far, np.nan).reshape(shape)


SUPPORT_TOLERANCE = 0.01
"""how thick the support's top is taken to be, as a fraction of the cameras' distance to the object: the plane lies
this far above the support's top, and shared points this close above it are the support's too"""
SUPPORT_QUANTILE = 0.01
"""the lowest points every camera sees: this quantile of their heights (a few stray points below do not count)"""
SUPPORT_REACH = 2.0
"""the support is looked for under the object and around it: within this many radii of the sphere every camera sees
whole, around the vertical axis through its centre, and on the cameras' side (`between_cameras`)"""


def between_cameras(points: np.ndarray, cameras: list[Camera], up: np.ndarray) -> np.ndarray:
    """(N,) whether each point lies, seen from above, inside the hull of the camera centres: what the object stands
    on reaches towards the cameras, a wall behind a half-circle capture does not."""
    from scipy.spatial import Delaunay, QhullError

    basis = np.linalg.svd(np.eye(3) - np.outer(up, up))[0][:, :2]  # two horizontal axes
    centres = np.array([c.center for c in cameras]) @ basis
    try:
        return Delaunay(centres).find_simplex(points @ basis) >= 0
    except QhullError:  # the centres on a line: no hull to tell the cameras' side by
        return np.ones(len(points), dtype=bool)


def support_height(points: np.ndarray, cameras: list[Camera], up: np.ndarray, centre: np.ndarray,
                   radius: float) -> float | None:
    """Height (along `up`) of the level plane the object stands on, from the sparse points (N, 3) under and around it
    (SUPPORT_REACH, `between_cameras`): the object is whole in every frame, what it stands on reaches out of some.
    The support's top is the split of the points' heights that leaves the fewest points every camera sees below it
    and the fewest others above (the lowest such split: an object floating over a floor keeps its underside), raised
    to the lowest points every camera sees where they lie within SUPPORT_TOLERANCE of it (a table's top in every
    frame around the object's foot); the plane lies SUPPORT_TOLERANCE above that top. None when no split beats
    none."""
    offset = points - centre
    height = offset @ up
    around = (np.linalg.norm(offset - np.outer(height, up), axis=1) <= SUPPORT_REACH * radius) & between_cameras(
        points, cameras, up)
    order = np.argsort(height[around])
    heights, shared = height[around][order], (in_view_fraction(points[around], cameras) >= 1.0)[order]
    errors = np.concatenate([[0], np.cumsum(shared)]) + (~shared).sum() - np.concatenate([[0], np.cumsum(~shared)])
    below = int(np.argmin(errors))  # the points below the best split
    if below == 0:
        return None
    tolerance = SUPPORT_TOLERANCE * float(np.mean([np.linalg.norm(c.center - centre) for c in cameras]))
    top = heights[below - 1]
    if shared.any():
        lowest_shared = float(np.quantile(heights[shared], SUPPORT_QUANTILE))
        if top < lowest_shared <= top + tolerance:
            top = lowest_shared
    return float(centre @ up + top) + tolerance


def view_seeds(grey: np.ndarray, camera: Camera, others: list[tuple[np.ndarray, Camera]], near: np.ndarray,
               far: np.ndarray, support: tuple[np.ndarray, float] | None = None) -> np.ndarray:
    """(h, w) int8 seeds of one view (OBJECT, BACKGROUND or UNKNOWN; module notes), from its grey image, its
    neighbours' (grey image, camera) and the depths (h, w) between which each pixel's ray may meet the object (NaN:
    it cannot). With a `support` plane (up, height), a pixel whose best match inside lies at or below it is
    background: the table, plinth or ground the object stands on."""
    hit = np.isfinite(near)
    seeds = np.full(grey.shape, BACKGROUND, np.int8)
    if not hit.any() or not others:
        return seeds
    matcher = Matcher(grey, camera, others, slice(None), slice(None), PARAMS, best_of=None)
    back = float(np.nanmax(far))
    near_t = torch.from_numpy(np.where(hit, near, back).astype(np.float32))
    far_t = torch.from_numpy(np.where(hit, far, back).astype(np.float32))
    pixels_per_inverse_depth = camera.fx * max(float(np.linalg.norm(cam.center - camera.center)) for _, cam in others)
    span = float(np.nanmax(1 / near[hit] - 1 / far[hit]))
    fraction = torch.linspace(0, 1, max(2, int(np.ceil(pixels_per_inverse_depth * span / STEP_PX))))[:, None, None]
    inside = 1 / (1 / near_t + fraction * (1 / far_t - 1 / near_t))
    count = max(2, int(np.ceil(pixels_per_inverse_depth / float(np.nanmin(far[hit])) / STEP_PX)))
    behind = 1 / (torch.linspace(1.0, 0.0, count + 1)[:-1, None, None] / far_t)

    everywhere = torch.ones(grey.shape, dtype=torch.bool)
    with torch.no_grad():
        best_in, scores_in = matcher.best(inside, everywhere)
        _, scores_behind = matcher.best(behind, everywhere)
    s_in, s_behind = scores_in.amax(0).numpy(), scores_behind.amax(0).numpy()
    depth = inside.gather(0, best_in[None])[0].numpy()
    matched_in = hit & (s_in >= MIN_SCORE) & (s_in >= s_behind + MARGIN)
    seeds[hit] = UNKNOWN
    seeds[matched_in] = OBJECT
    seeds[hit & (s_behind >= MIN_SCORE) & (s_behind >= s_in + MARGIN)] = BACKGROUND
    if support is not None:
        up, height = support
        points = camera.center + depth[..., None] * (camera_rays(camera) @ camera.c2w[:3, :3].T)
        seeds[matched_in & (points @ up <= height)] = BACKGROUND
    return seeds


FRAME_MARGIN = 0.05
"""the object may reach this fraction of the image's size past a frame's edges"""


def support_plane(cameras: list[Camera], centre: np.ndarray, points: np.ndarray | None
                  ) -> tuple[np.ndarray, float] | None:
    """(up, height) of the level plane the object stands on, from the scene's sparse `points` (N, 3) round the point
    `centre` the cameras look at (`support_height`); None without points or a split."""
    if points is None or not len(points):
        return None
    up = up_direction(cameras)
    height = support_height(points, cameras, up, centre, visible_sphere(cameras)[1])
    return None if height is None else (up, height)


def depth_seeds(greys: list[np.ndarray], cameras: list[Camera], centre: np.ndarray,
                support: tuple[np.ndarray, float] | None = None) -> list[np.ndarray]:
    """Each view's seeds (view_seeds) against its NEIGHBOURS nearest views (by their direction to `centre`), the
    object inside the space every camera sees (`common_view_depths`: the object is whole in every frame), above the
    `support` plane (`support_plane`), if any."""
    neighbours = neighbour_views(cameras, centre, NEIGHBOURS, PARAMS.max_baseline_deg)
    return [view_seeds(greys[i], cameras[i], [(greys[j], cameras[j]) for j in neighbours[i]],
                       *common_view_depths(cameras[i], cameras, FRAME_MARGIN), support) for i in range(len(cameras))]
