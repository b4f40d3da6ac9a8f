"""Multi-view stereo depth inside the visual hull, and the hull carved by what the depths see as
empty: concavities and holes the silhouettes cannot see (a bowl's cavity, a torus hole the masks
filled) open up.

**Depth.** Every view is swept with fronto-parallel planes (camera-space depths) over the depth range
of the carved hull it sees (open3d ray casting) and `beyond` past it; each plane warps the nearest
views onto it, and the zero-mean normalised cross-correlation (NCC) over a window of the blurred
images scores the match. A plane's score is the mean of its best `best_of` neighbours (occluded
ones do not vote); a second pass refines each pixel around its best plane, with a parabola through
the best. A depth is kept when its score reaches `min_score`, it is not at the end of the range,
no specular highlight covers it (a pixel much brighter than its surroundings: a highlight's mirror
image lies behind the surface, and views near each other agree on it), its surface (the depth map's
own normal) is seen within `max_incidence_deg` of head-on, and `min_consistent` neighbour depth maps
agree with it. Pixels left without a depth take the one a sweep with the larger `fallback_window`
finds, under the same checks (a noisy, weakly lit cavity matches over more pixels).

**Passes.** Depths and carving repeat `passes` times, each round inside the surface the previous one
left (a bowl's cavity opens further once its first round removed the lid the silhouettes left).

**Carving.** Each voxel inside the hull gets the median, over the views that see it in front of
their surface or at most `band_voxels` behind it, of (observed depth - voxel depth) clipped to the
band: a truncated signed distance whose median, unlike a mean, lets no small group of wrong depths
carve a tunnel. The hull's field (negative inside) takes the maximum with it (less `margin_voxels`),
so stereo only removes volume the silhouettes left, never adds it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import torch
import torch.nn.functional as F

from dpi.capture.cameras import Camera
from dpi.capture.consistency import raycasting_scene

BAND_VOXELS = 3.0
"""truncation of the carving distance, in hull voxels"""
MARGIN_VOXELS = 0.5
"""the carving distance must exceed this (hull voxels): depth noise does not shave the hull"""
MAX_INCIDENCE_DEG = 70.0
"""depths whose surface (the depth map's own normal) is seen more than this from head-on are dropped
(a window on a grazing surface spans more depth than the sweep resolves; 90: off)"""
MIN_CONSISTENT = 2
"""neighbour depth maps that must agree with a depth (within `consistency` of it)"""
BEST_OF = 4
"""a plane's score is the mean NCC of its best `best_of` neighbours (occlusion-robust)"""
BEYOND = 0.5
"""planes continue this fraction of the hull's depth extent past its far side (holes)"""




@dataclass(frozen=True)
class StereoParams:
    """Parameters of the plane sweep, the depth filters and the carving: fixed by dpi (no config key; tests
    vary them), the geometry stage's `stereo` switch turns the whole step on or off."""

    neighbours: int = 6
    """views each depth map is matched against (nearest viewing directions)"""
    planes: int = 64
    """depth planes over the hull's depth range per view (first pass)"""
    refine: int = 9
    """per-pixel depths around the best plane, one plane step either side (second pass)"""
    window: int = 11
    """NCC window side in pixels"""
    fallback_window: int = 15
    """pixels left without a consistent depth at `window` take the depth a sweep with this larger window
    finds, if that one is consistent (a noisy, weakly lit patch such as a bowl's cavity matches over
    more pixels; at most `window`: off)"""
    min_score: float = 0.3
    """mean NCC a depth must reach"""
    blur_px: float = 1.0
    """Gaussian blur (pixels) of the images before matching: noise and aliased texture do not match"""
    consistency: float = 0.01
    """relative depth difference under which two views agree"""
    highlight_ratio: float = 1.3
    """pixels brighter than this times their surroundings' mean (and 3 px around) get no depth (0: off)"""
    votes: int = 3
    """views that must have a depth at a voxel for it to be carved"""
    max_baseline_deg: float = 50.0
    """neighbours see the object's centre within this angle of the reference view"""
    passes: int = 2
    """rounds of depth maps and carving, each swept inside the surface the previous one carved: depths
    in front of it are no longer hypotheses, so cavities the first round half opened open further"""
    ground_fit: float = 0.02
    """the ground test (dpi.preprocess.ground) runs only when at least this fraction of the background
    pixels near the object reach its `GROUND_SEED` under the fitted ground plane (a plain ground: none)"""


def grey(image: np.ndarray, blur_px: float) -> np.ndarray:
    """Luminance of a linear RGB image, sRGB-encoded (matching works on perceptual contrast) and blurred."""
    import cv2

    from dpi.io.images import linear_to_srgb, luminance

    out = linear_to_srgb(np.clip(luminance(image), 0, 1)).astype(np.float32)
    return cv2.GaussianBlur(out, (0, 0), blur_px) if blur_px > 0 else out


def camera_rays(camera: Camera) -> np.ndarray:
    """Camera-space ray directions (h, w, 3) through pixel centres, scaled to depth 1 (z = -1, OpenGL)."""
    ys, xs = np.meshgrid(np.arange(camera.height) + 0.5, np.arange(camera.width) + 0.5, indexing="ij")
    return np.stack([(xs - camera.cx) / camera.fx, -(ys - camera.cy) / camera.fy, -np.ones_like(xs)], -1)


def hull_depth_range(scene, camera: Camera, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """Camera-space depths (h, w) where each pixel's ray enters and leaves a closed mesh (an open3d
    RaycastingScene, `dpi.capture.consistency.raycasting_scene`, that lies within `reach` of the camera); inf where it misses."""
    import open3d as o3d

    rays = camera_rays(camera)
    scale = np.linalg.norm(rays, axis=-1)
    direction = (rays / scale[..., None]) @ camera.c2w[:3, :3].T
    origin = np.broadcast_to(camera.center, direction.shape)
    entry = scene.cast_rays(o3d.core.Tensor(np.concatenate([origin, direction], -1).astype(np.float32)))
    near = entry["t_hit"].numpy() / scale
    back = scene.cast_rays(o3d.core.Tensor(np.concatenate([origin + reach * direction, -direction],
                                                          -1).astype(np.float32)))
    far = (reach - back["t_hit"].numpy()) / scale
    far[~np.isfinite(near)] = np.inf
    return near.astype(np.float32), far.astype(np.float32)


def neighbour_views(cameras: list[Camera], centre: np.ndarray, count: int, max_angle_deg: float) -> list[list[int]]:
    """For every view, the `count` other views whose direction to `centre` is closest to its own
    (at least 2 deg apart: no baseline, no depth), within `max_angle_deg`."""
    directions = np.array([c.center - centre for c in cameras])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    angles = np.degrees(np.arccos(np.clip(directions @ directions.T, -1, 1)))
    result = []
    for i in range(len(cameras)):
        order = [j for j in np.argsort(angles[i]) if j != i and 2.0 <= angles[i, j] <= max_angle_deg]
        result.append(order[:count])
    return result


def _box(x: torch.Tensor, window: int) -> torch.Tensor:
    """Mean over a window x window neighbourhood of (n, c, h, w) maps (edges: mean of what is inside), from
    running sums along each axis (in float64, so differences of large sums stay exact): its cost does not grow
    with the window. An even window is taken one wider, centred."""
    half = window // 2
    span = 2 * half + 1

    def window_sums(x: torch.Tensor, dim: int) -> torch.Tensor:
        n = x.shape[dim]
        pad = [half + 1, half, 0, 0] if dim == 3 else [0, 0, half + 1, half]
        running = torch.cumsum(F.pad(x, pad), dim, dtype=torch.float64)
        return running.narrow(dim, span, n) - running.narrow(dim, 0, n)

    def counts(n: int) -> torch.Tensor:
        i = torch.arange(n)
        return ((i + half).clamp(max=n - 1) - (i - half).clamp(min=0) + 1).double()

    h, w = x.shape[-2:]
    sums = window_sums(window_sums(x, 3), 2)
    return (sums / (counts(h)[:, None] * counts(w)[None, :])).to(x.dtype)


class Matcher:
    """NCC of a reference view against its neighbours for per-pixel depth hypotheses, on a crop."""

    def __init__(self, ref: np.ndarray, camera: Camera, others: list[tuple[np.ndarray, Camera]],
                 rows: slice, cols: slice, cfg: StereoParams, best_of: int | None = BEST_OF):
        self.cfg = cfg
        self.best_of = best_of
        rays = torch.from_numpy(camera_rays(camera)[rows, cols].astype(np.float32))
        a = torch.from_numpy(np.ascontiguousarray(ref[rows, cols]))[None, None]
        self.a = a
        self.mean_a = _box(a, cfg.window)
        self.var_a = (_box(a * a, cfg.window) - self.mean_a ** 2).clamp_min(1e-6)
        self.views = []
        for image, cam in others:
            w2c = np.linalg.inv(cam.c2w)
            rot = torch.from_numpy((w2c[:3, :3] @ camera.c2w[:3, :3]).astype(np.float32))
            offset = torch.from_numpy((w2c[:3, :3] @ camera.center + w2c[:3, 3]).astype(np.float32))
            self.views.append((torch.from_numpy(image)[None, None], rays @ rot.T, offset, cam))

    def scores(self, z: torch.Tensor) -> torch.Tensor:
        """Mean NCC of the best `best_of` neighbours (P, h, w) for depths z (P, h, w) (-1: no match; `best_of`: BEST_OF
        unless the matcher was given another; None: the mean over the neighbours whose frame holds the point)."""
        window, per_view, seen = self.cfg.window, [], []
        for image, direction, offset, cam in self.views:
            p = direction[None] * z[..., None] + offset
            depth = -p[..., 2]
            x = cam.fx * p[..., 0] / depth + cam.cx
            y = -cam.fy * p[..., 1] / depth + cam.cy
            grid = torch.stack([2 * x / cam.width - 1, 2 * y / cam.height - 1], -1)
            b = F.grid_sample(image.expand(len(z), -1, -1, -1), grid, align_corners=False, padding_mode="border")
            mean_b = _box(b, window)
            var_b = (_box(b * b, window) - mean_b ** 2).clamp_min(1e-6)
            ncc = ((_box(self.a * b, window) - self.mean_a * mean_b) / torch.sqrt(self.var_a * var_b))[:, 0]
            valid = (depth > 1e-3) & (x >= 0) & (x < cam.width) & (y >= 0) & (y < cam.height)
            per_view.append(torch.where(valid, ncc, torch.tensor(-1.0)))
            seen.append(valid)
        if self.best_of is None:
            count = torch.stack(seen).sum(0)
            total = torch.where(torch.stack(seen), torch.stack(per_view), torch.tensor(0.0)).sum(0)
            return torch.where(count > 0, total / count.clamp_min(1), torch.tensor(-1.0))
        best_of = min(self.best_of, len(per_view))
        return torch.stack(per_view).topk(best_of, dim=0).values.mean(0)

    def best(self, z: torch.Tensor, allowed: torch.Tensor, batch: int = 16) -> tuple[torch.Tensor, torch.Tensor]:
        """Index of the best hypothesis per pixel and the scores of all (P, h, w); disallowed ones score -2."""
        scores = torch.cat([self.scores(z[i:i + batch]) for i in range(0, len(z), batch)])
        scores = torch.where(allowed, scores, torch.tensor(-2.0))
        return scores.argmax(0), scores


def sweep_depth(ref: np.ndarray, camera: Camera, others: list[tuple[np.ndarray, Camera]], near: np.ndarray,
                far: np.ndarray, cfg: StereoParams) -> tuple[np.ndarray, np.ndarray]:
    """Depth (h, w; camera-space, 0 where none) and its score (mean NCC) for one view.

    Two passes: `planes` fronto-parallel planes over the view's hull depth range (and `beyond` past
    it), then `refine` per-pixel depths over the best plane's neighbourhood, with a parabola through
    the best of those. ref, others' images: grey (h, w); near/far: hull depth range (inf: outside)."""
    inside = np.isfinite(near)
    depth_map, score_map = np.zeros_like(near), np.full_like(near, -1.0)
    if not inside.any() or not others:
        return depth_map, score_map
    pad = cfg.window
    ys, xs = np.nonzero(inside)
    rows = slice(max(ys.min() - pad, 0), ys.max() + pad + 1)
    cols = slice(max(xs.min() - pad, 0), xs.max() + pad + 1)
    matcher = Matcher(ref, camera, others, rows, cols, cfg)
    crop_inside = torch.from_numpy(inside[rows, cols])
    crop_near = torch.from_numpy(np.where(inside, near, 0)[rows, cols])
    z_lo, z_hi = float(near[inside].min()), float(far[inside].max())
    z_hi += BEYOND * (z_hi - z_lo)
    planes = torch.linspace(z_lo, z_hi, cfg.planes)
    step = float(planes[1] - planes[0])
    shape = crop_inside.shape
    z = planes[:, None, None].expand(-1, *shape)
    allowed = (z >= crop_near - 2 * step) & crop_inside
    best, _ = matcher.best(z, allowed)
    interior = (best > 0) & (best < cfg.planes - 1)
    offsets = torch.linspace(-step, step, cfg.refine)
    z = planes[best][None] + offsets[:, None, None]
    best, scores = matcher.best(z, crop_inside[None].expand(cfg.refine, -1, -1))
    k = best.clamp(1, cfg.refine - 2)
    s0, s1, s2 = (scores.gather(0, (k + d)[None])[0] for d in (-1, 0, 1))
    curvature = s0 - 2 * s1 + s2
    shift = torch.where(curvature < -1e-6, 0.5 * (s0 - s2) / curvature, torch.zeros_like(s1)).clamp(-0.5, 0.5)
    depth = z.gather(0, k[None])[0] + shift * (offsets[1] - offsets[0])
    score = scores.gather(0, best[None])[0]
    keep = crop_inside & interior & (score >= cfg.min_score)
    depth_map[rows, cols] = torch.where(keep, depth, torch.tensor(0.0)).numpy()
    score_map[rows, cols] = score.numpy()
    return depth_map, score_map


def observed_depth(depth: np.ndarray, camera: Camera, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The depth map's value at the pixel each world point (N, 3) falls in (0: none, or outside the
    frame) and the points' own camera-space depths (N,)."""
    xy, z = camera.project(points)
    col, row = np.floor(xy[:, 0]).astype(np.int64), np.floor(xy[:, 1]).astype(np.int64)
    ok = (z > 0) & (col >= 0) & (col < camera.width) & (row >= 0) & (row < camera.height)
    observed = np.zeros(len(points), np.float32)
    observed[ok] = depth[row[ok], col[ok]]
    return observed, z


def consistent(depths: list[np.ndarray], cameras: list[Camera], neighbours: list[list[int]],
               cfg: StereoParams) -> list[np.ndarray]:
    """The depth maps with depths that fewer than `min_consistent` neighbour maps agree with set to 0."""
    out = []
    for i, (depth, cam) in enumerate(zip(depths, cameras)):
        valid = depth > 0
        points = (camera_rays(cam)[valid] * depth[valid][:, None]) @ cam.c2w[:3, :3].T + cam.center
        agree = np.zeros(len(points), np.int32)
        for j in neighbours[i]:
            seen, z = observed_depth(depths[j], cameras[j], points)
            agree += (seen > 0) & (np.abs(seen - z) <= cfg.consistency * z)
        kept = np.zeros_like(depth)
        kept[valid] = np.where(agree >= MIN_CONSISTENT, depth[valid], 0.0)
        out.append(kept)
    return out


def free_space(points: np.ndarray, depths: list[np.ndarray], cameras: list[Camera], band: float,
               votes: int) -> np.ndarray:
    """A robust truncated signed distance (N,) of world points from the surfaces the depth maps see,
    positive in front: the median over views of (observed depth - point depth) clipped to +-band,
    over the views that see the point in front of their surface or less than `band` behind it
    (farther behind, the view's surface hides it: no evidence). -inf where fewer than `votes` views
    count. A median, unlike open3d's mean, lets no group of wrong depths carve a tunnel."""
    points = np.asarray(points, np.float32)
    values = np.full((len(cameras), len(points)), np.nan, np.float32)
    for i, (depth, cam) in enumerate(zip(depths, cameras)):
        observed, z = observed_depth(depth, cam, points)
        s = observed - z
        values[i] = np.where((observed > 0) & (s >= -band), np.minimum(s, band), np.nan)
    count = np.isfinite(values).sum(0)
    median = np.full(len(points), -np.inf, np.float32)
    counted = count >= votes
    median[counted] = np.nanmedian(values[:, counted], axis=0)
    return median


def highlights(image: np.ndarray, mask: np.ndarray, ratio: float) -> np.ndarray:
    """Specular highlights (h, w) bool: inside the mask, pixels whose blurred luminance exceeds `ratio`
    times the mean of their masked surroundings (Gaussian, 8 px), grown by 3 px."""
    import cv2

    from dpi.io.images import luminance

    lum = cv2.GaussianBlur(luminance(image).astype(np.float32), (0, 0), 2)
    weight = mask.astype(np.float32)
    surroundings = cv2.GaussianBlur(lum * weight, (0, 0), 8) / np.maximum(cv2.GaussianBlur(weight, (0, 0), 8), 1e-3)
    bright = ((lum > ratio * surroundings) & mask).astype(np.uint8)
    return cv2.dilate(bright, np.ones((7, 7), np.uint8)) > 0


def grazing(depth: np.ndarray, camera: Camera, max_deg: float, step: int = 2) -> np.ndarray:
    """Pixels (h, w) whose depth's surface normal, from the depth map's points `step` px either side,
    is more than `max_deg` from the pixel's ray (pixels without both neighbours: False)."""
    rays = camera_rays(camera)
    points = rays * depth[..., None]
    valid = depth > 0
    dx = np.zeros_like(points)
    dy = np.zeros_like(points)
    dx[:, step:-step] = points[:, 2 * step:] - points[:, :-2 * step]
    dy[step:-step] = points[2 * step:] - points[:-2 * step]
    known = np.zeros_like(valid)
    known[step:-step, step:-step] = (valid[step:-step, 2 * step:] & valid[step:-step, :-2 * step]
                                     & valid[2 * step:, step:-step] & valid[:-2 * step, step:-step])
    normal = np.cross(dx, dy)
    length = np.linalg.norm(normal, axis=-1) * np.linalg.norm(rays, axis=-1)
    cos = np.abs((normal * rays).sum(-1)) / np.maximum(length, 1e-12)
    return known & valid & (cos < np.cos(np.radians(max_deg)))


def depth_maps(cameras: list[Camera], images: list[np.ndarray], masks: list[np.ndarray], vertices: np.ndarray,
               faces: np.ndarray, cfg: StereoParams) -> list[np.ndarray]:
    """Filtered stereo depth maps (camera-space depth, 0: none) of every view, searched inside the
    depth range of the closed mesh (vertices, faces) that contains the object (the carved hull)."""
    from dpi.preprocess.hull import axes_centre

    scene = raycasting_scene(vertices, faces)
    neighbours = neighbour_views(cameras, axes_centre(cameras), cfg.neighbours, cfg.max_baseline_deg)
    greys = [grey(image, cfg.blur_px) for image in images]
    ranges = [hull_depth_range(scene, cam, 2 * float(np.linalg.norm(vertices - cam.center, axis=1).max()))
              for cam in cameras]
    usable = [mask & ~highlights(image, mask, cfg.highlight_ratio) if cfg.highlight_ratio else mask
              for image, mask in zip(images, masks)]

    def raw(window: int) -> list[np.ndarray]:
        """Every view's filtered depth map at one NCC window, before the consistency check."""
        wcfg = replace(cfg, window=window)
        depths = []
        for i, cam in enumerate(cameras):
            depth, _ = sweep_depth(greys[i], cam, [(greys[j], cameras[j]) for j in neighbours[i]], *ranges[i], wcfg)
            keep = usable[i]
            if MAX_INCIDENCE_DEG < 90:
                keep = keep & ~grazing(depth, cam, MAX_INCIDENCE_DEG)  # not in place: keep may be masks[i]
            depths.append(np.where(keep, depth, 0.0).astype(np.float32))
        return depths

    fine = consistent(raw(cfg.window), cameras, neighbours, cfg)
    if cfg.fallback_window <= cfg.window:
        return fine
    merged = [np.where(f > 0, f, c) for f, c in zip(fine, raw(cfg.fallback_window))]
    return [np.where(f > 0, f, m) for f, m in zip(fine, consistent(merged, cameras, neighbours, cfg))]


def carve_with_depths(field: np.ndarray, origin: np.ndarray, size: float, cameras: list[Camera],
                      depths: list[np.ndarray], cfg: StereoParams) -> np.ndarray:
    """The carved field (negative inside) with what the depth maps see as empty removed (`free_space`)."""
    points = origin + np.stack(np.indices(field.shape), -1) * size
    near = field < BAND_VOXELS * size
    out = field.copy()
    free = free_space(points[near], depths, cameras, BAND_VOXELS * size, cfg.votes)
    out[near] = np.maximum(field[near], free - MARGIN_VOXELS * size)
    return out
