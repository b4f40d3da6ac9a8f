"""Foreground masks from photos and cameras: classical methods, or a learned segmenter the user brings.

Two classical methods, chosen per image (a learned segmenter, dpi.preprocess.segmenter, takes their place when
`weights` names one: prompted by what GrabCut's first prior and the sparse points say, `view_prompt`, its masks are
kept as it cuts them):
- **colour keying** when the background is uniform (the image border has one colour, as in a
  studio or turntable capture): foreground is every pixel whose colour differs from the key;
- **GrabCut** otherwise, started from a soft prior: the disc of the sphere every camera sees whole
  (the object is what the cameras look at) is *probably foreground*, the rest of the image
  *probably background*, and a thin strip along the border *background*. The object's sparse 3-D
  points (from structure from motion) add the convex hull of their projections, grown by a margin,
  as probably foreground, and that hull shrunk by a margin as *foreground*: a region, never single
  points, so a few stray points cannot force a wrong region into the mask.

**Parallax seeds** (dpi.preprocess.depth_seeds, `parallax`): where the views' parallax puts a pixel on the object
(inside the space every camera sees, above what it stands on) GrabCut's first pass takes it as foreground, where it
puts it behind, as background in every pass: a busy background that colour cannot tell from the object.

**Consensus rounds** then refine the GrabCut masks with what the views agree on: the visual hull
of the current masks, carved where at least a fraction of the views see a voxel outside them (so
a part that some views miss, or a patch of background that one view takes for the object, does
not matter), is projected into every view, and GrabCut decides only in a band around the
projected outline: deeper inside is foreground, farther outside background. The hull is cut at the
plane the object stands on (where the sparse points show one): below it is the plinth or table. Each round lowers
the votes and narrows the band. Where GrabCut still disagrees with the projection, the
projection is the mask.

Either way the largest connected component is kept and small holes are filled; holes larger
than `FILL_HOLES_BELOW` of the object (the hole of a torus) are kept.

**Confidence** (dpi.preprocess.mask_confidence): each final mask is checked against the object's sparse points
(the share inside it), the image's edges (the share of its outline on one) and the hull that all the masks carve
(its IoU with that outline, `agreement`, against the median view's); a view that fails one is unreliable, and the
summary, the log and the report name it and why.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
import torch
from pydantic import Field

from dpi.capture.cameras import Camera
from dpi.capture.consistency import mask_iou
from dpi.capture.load import MIN_DERIVED_VIEWS
from dpi.capture.model import CaptureError
from dpi.io.images import read_image, resize, resize_mask, to_uint8, working_size, write_mask
from dpi.io.settings import settings
from dpi.preprocess.hull import cut_below, marching_cubes, visible_sphere, visual_hull
from dpi.preprocess.depth_seeds import BACKGROUND, OBJECT, PARAMS, depth_seeds, support_plane
from dpi.preprocess.mask_confidence import (AGREEMENT_VOTE_SHARE, MASK_AGREEMENT, edge_support, frame_contact,
                                           point_coverage, verdict)
from dpi.preprocess.morphology import grow, shrink
from dpi.preprocess.segmenter import Prompt
from dpi.preprocess.stereo import grey

log = logging.getLogger(__name__)

METHODS = ("auto", "grabcut", "key", "learned")


GRABCUT_ITERATIONS = 5
WITHOUT_POINTS = ("no sparse point of the object was triangulated from the photos, so its masks started from the "
                  "sphere the cameras look at alone: the object too small or too large in the frames, textureless, or "
                  "the photos blurred")
"""the likely cause when masks cut without any of the object's sparse points fail"""
PROMPT_POINTS = 8
"""a segmenter's positive and negative prompt points per view, at most (spread over the points that qualify)"""

HULL_CORE = 0.12
"""the points' hull shrunk by this fraction of its size is foreground for sure (a region; 0: off)"""
HULL_MARGIN = 0.05
"""growth of the projected object points' hull that is probably foreground, as a fraction of its size"""
KEY_MAX_SPREAD = 0.06
"""the background is uniform when the border's colours (sRGB, 0-1) spread less than this"""
KEY_THRESHOLD = 0.1
"""keying: a pixel is foreground when its sRGB colour is farther than this from the key colour"""
MIN_POINTS = 30
"""with fewer object points the first prior is the sphere alone"""
OUTLIER_STD_RATIO = 2.0
"""object points farther from their neighbours than the mean plus this many standard deviations
are dropped before the hull (open3d's statistical outlier removal; 0: keep all)"""


SPHERE_FRACTION = 0.7
"""first GrabCut prior: the disc of this fraction of the sphere every camera sees whole is probably foreground"""
FILL_HOLES_BELOW = 0.01
"""holes smaller than this fraction of the mask's area are filled"""
CONSENSUS_ROUNDS = ((0.25, 0.08), (0.125, 0.04))
"""one consensus round per entry: (the fraction of the views that must see a voxel outside their masks to carve
it from the hull, at least 2 views; the half-width of the band around the projected hull's outline in which
GrabCut decides, as a fraction of the object's size in the image)"""
CONSENSUS_RESOLUTION = 96
"""voxels along the longest side of the consensus hull's box"""


@settings
class MaskConfig:
    """Settings of mask extraction."""

    method: str = "auto"
    """auto (the learned segmenter when `weights` names one, else keying on a uniform background, else GrabCut) |
    grabcut | key | learned"""
    segmenter: Literal["exported", "sam", "sam2", "rembg"] = "exported"
    """the kind of segmenter `weights` holds (dpi.preprocess.segmenter): a torch.export program (.pt2), a Segment
    Anything or SAM 2 checkpoint, or a salient-object ONNX model (rembg's)"""
    weights: str | None = None
    """the segmenter's file: a path, or a name in $DPI_WEIGHTS; None: the classical methods alone"""
    parallax: bool = True
    """seed GrabCut with what the views' parallax puts on the object and behind it (dpi.preprocess.depth_seeds): a
    busy background colour cannot tell from the object; off for a plain one, a few seconds less"""
    max_size: Annotated[int, Field(ge=16)] | None = 480
    """longer image side (px) the masks are computed at: larger photos are area-downsampled (with their
    cameras) and the masks upsampled to the photos' size (GrabCut's fixed smoothness is tuned to small
    images and costs seconds per view at photo size); None: the photos' own size"""


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


def _border_background(labels: np.ndarray, border: float = 0.03) -> None:
    """Mark a strip along the image border (a `border` fraction of the shorter side) as background."""
    import cv2

    b = max(1, int(round(border * min(labels.shape))))
    for strip in (labels[:b], labels[-b:], labels[:, :b], labels[:, -b:]):
        strip[...] = cv2.GC_BGD


def in_frame(camera: Camera, points: np.ndarray) -> np.ndarray:
    """Pixel positions (N, 2) of the points (N, 3) in front of `camera` that project into its frame."""
    xy, depth = camera.project(points)
    inside = (depth > 0) & (xy[:, 0] >= 0) & (xy[:, 0] < camera.width) & (xy[:, 1] >= 0) & (xy[:, 1] < camera.height)
    return xy[inside]


def points_hull(camera: Camera, points: np.ndarray) -> np.ndarray | None:
    """Convex hull (h, w) of the projections of the points (N, 3) in the view; None when fewer than 3 are in it."""
    import cv2

    xy = in_frame(camera, points)
    if len(xy) < 3:
        return None
    hull = cv2.convexHull(np.round(xy - 0.5).astype(np.int32).reshape(-1, 1, 2))
    region = np.zeros((camera.height, camera.width), np.uint8)
    cv2.fillConvexPoly(region, hull, 1)
    return region > 0


def drop_outliers(points: np.ndarray, std_ratio: float, neighbours: int = 8) -> np.ndarray:
    """Points (N, 3) without statistical outliers: those whose mean distance to their `neighbours`
    nearest points exceeds the average by `std_ratio` standard deviations (open3d)."""
    import open3d as o3d

    if std_ratio <= 0 or len(points) <= neighbours:
        return points
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, np.float64)))
    _, keep = cloud.remove_statistical_outlier(nb_neighbors=neighbours, std_ratio=std_ratio)
    return np.asarray(points)[np.asarray(keep, dtype=np.int64)]


def with_seeds(labels: np.ndarray, seeds: np.ndarray | None) -> np.ndarray:
    """GrabCut labels with the parallax seeds (`parallax_seeds`) set: object seeds foreground, background seeds
    background."""
    import cv2

    if seeds is None:
        return labels
    labels = labels.copy()
    labels[seeds == BACKGROUND] = cv2.GC_BGD
    labels[seeds == OBJECT] = cv2.GC_FGD
    return labels


def first_prior(camera: Camera, sphere: tuple[np.ndarray, float], points: np.ndarray | None = None,
                seeds: np.ndarray | None = None) -> np.ndarray:
    """GrabCut labels (h, w) of the first pass: the projected disc of `sphere` (centre, radius) and
    the grown hull of the object's projected points (N, 3) probably foreground, the hull's core
    foreground, the rest probably background and a strip along the image border background; then the parallax
    `seeds` (`with_seeds`)."""
    import cv2

    xy, depth = camera.project(np.asarray(sphere[0], dtype=np.float64)[None])
    r = camera.fx * sphere[1] / max(float(depth[0]), 1e-9)
    yy, xx = np.mgrid[: camera.height, : camera.width]
    region = (xx + 0.5 - xy[0, 0]) ** 2 + (yy + 0.5 - xy[0, 1]) ** 2 <= r * r
    core = np.zeros_like(region)
    hull = points_hull(camera, points) if points is not None and len(points) >= MIN_POINTS else None
    if hull is not None:
        size = max(np.sqrt(hull.sum()), 1.0)
        region |= grow(hull, int(round(HULL_MARGIN * size)))
        if HULL_CORE > 0:
            core = shrink(hull, int(round(HULL_CORE * size)))
    labels = np.where(region, cv2.GC_PR_FGD, cv2.GC_PR_BGD).astype(np.uint8)
    labels[core] = cv2.GC_FGD
    _border_background(labels)
    return with_seeds(labels, seeds)


def band_prior(outline: np.ndarray, band: int) -> np.ndarray:
    """GrabCut labels (h, w) around a projected outline: probably foreground / background within
    `band` pixels inside / outside it, foreground deeper inside, background farther outside."""
    import cv2

    labels = np.full(outline.shape, cv2.GC_BGD, np.uint8)
    labels[grow(outline, band)] = cv2.GC_PR_BGD
    labels[outline] = cv2.GC_PR_FGD
    labels[shrink(outline, band)] = cv2.GC_FGD
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


def choose_method(image8: np.ndarray, cfg: MaskConfig, segmenter=None) -> tuple[str, np.ndarray, float]:
    """(method, border colour, its spread) for one 8-bit image: the configured method, or for auto the learned
    segmenter when loaded, else keying on a uniform border, else GrabCut."""
    colour, spread = border_colour(image8)
    method = cfg.method
    if method == "auto":
        method = "learned" if segmenter is not None else "key" if spread < KEY_MAX_SPREAD else "grabcut"
    return method, colour, spread


def spread_points(xy: np.ndarray, count: int) -> np.ndarray:
    """At most `count` of the pixel positions (N, 2), spread over them (farthest-point order from their centre)."""
    if len(xy) <= count:
        return xy
    chosen = [int(np.argmin(np.linalg.norm(xy - xy.mean(0), axis=1)))]
    distance = np.linalg.norm(xy - xy[chosen[0]], axis=1)
    while len(chosen) < count:
        chosen.append(int(np.argmax(distance)))
        distance = np.minimum(distance, np.linalg.norm(xy - xy[chosen[-1]], axis=1))
    return xy[chosen]


def points_on(camera: Camera, points: np.ndarray | None, where: np.ndarray) -> np.ndarray:
    """Pixel positions (N, 2) of the points (N, 3) in front of `camera` whose pixel lies in `where` (h, w)."""
    if points is None or not len(points):
        return np.zeros((0, 2))
    xy = in_frame(camera, points)
    return xy[where[xy[:, 1].astype(int), xy[:, 0].astype(int)]]


def view_prompt(camera: Camera, labels: np.ndarray, points: np.ndarray | None,
                scene_points: np.ndarray | None) -> Prompt:
    """A segmenter's prompt for one view from GrabCut's first labels: the object's points (N, 3) that land on its
    sure foreground as positive points, the scene's points that land on background as negative ones (PROMPT_POINTS
    of each at most, spread), and the box of where the object probably is; without positive points, the middle of
    that region."""
    import cv2

    region = (labels == cv2.GC_FGD) | (labels == cv2.GC_PR_FGD)
    if not region.any():
        region = np.ones(labels.shape, bool)
    ys, xs = np.nonzero(region)
    box = np.array([xs.min(), ys.min(), xs.max() + 1, ys.max() + 1], np.float64)
    positive = spread_points(points_on(camera, points, labels == cv2.GC_FGD), PROMPT_POINTS)
    if not len(positive):
        positive = np.array([[xs.mean() + 0.5, ys.mean() + 0.5]])
    background = (labels == cv2.GC_BGD) | (labels == cv2.GC_PR_BGD)
    negative = spread_points(points_on(camera, scene_points, background), PROMPT_POINTS)
    return Prompt(labels, positive, negative, box)


def object_mask(image: np.ndarray, camera: Camera, cfg: MaskConfig, sphere: tuple[np.ndarray, float],
                points: np.ndarray | None = None, segmenter=None,
                seeds: np.ndarray | None = None, scene_points: np.ndarray | None = None) -> tuple[np.ndarray, str]:
    """First-pass foreground mask (h, w) of one linear RGB image, and the method used ("key", "grabcut" or
    "learned": `segmenter`, a loaded dpi.preprocess.segmenter, prompted by `view_prompt`).

    GrabCut and the segmenter start from `first_prior` of the sphere (centre, radius), the object's points (N, 3) and
    the view's parallax seeds; the segmenter's negative points come from `scene_points`."""
    from dpi.preprocess.segmenter import learned_mask

    image8 = to_uint8(image)
    method, colour, spread = choose_method(image8, cfg, segmenter)
    if method == "key":
        mask = key_mask(image8, colour, max(KEY_THRESHOLD, 2 * spread))
    elif method == "learned":
        prompt = view_prompt(camera, first_prior(camera, sphere, points, seeds), points, scene_points)
        mask = learned_mask(segmenter, image8, prompt)
    else:
        mask = grabcut(image8, first_prior(camera, sphere, points, seeds), GRABCUT_ITERATIONS)
    return clean_mask(mask, FILL_HOLES_BELOW), method


def mesh_silhouette(camera: Camera, vertices: np.ndarray, faces: np.ndarray, supersample: int = 4) -> np.ndarray:
    """Pixels (h, w) at least half covered by a triangle mesh in the view: rays through a `supersample` times finer
    grid of pixel centres cast against the mesh (open3d), averaged per pixel. (A polygon fill of all triangles at
    once would cancel where an even number of them overlap, as a closed mesh's front and back do.)"""
    from dpi.capture.consistency import raycasting_scene, silhouette

    s = supersample
    fine = silhouette(raycasting_scene(vertices, faces), camera.resized(camera.width * s, camera.height * s))
    return fine.reshape(camera.height, s, camera.width, s).mean(axis=(1, 3)) >= 0.5


def consensus_outlines(cameras: list[Camera], masks: list[np.ndarray], votes: int, resolution: int,
                       support: tuple[np.ndarray, float] | None = None) -> list[np.ndarray]:
    """Each view's projection of the visual hull carved from `masks` where `votes` views see a voxel outside, and
    below the `support` plane (up, height) if any: the object stands on it, and a silhouette hull's skirt down to it
    (the space under a bulge that no view sees round) is the plinth or table in front of the object's foot."""
    field, origin, size, _ = visual_hull(cameras, masks, resolution, outside_votes=votes)
    if support is not None:
        field = cut_below(field, origin, size, *support)
    vertices, faces = marching_cubes(field, origin, size)
    return [mesh_silhouette(camera, vertices, faces) for camera in cameras]


def refine_masks(images8: list[np.ndarray | None], cameras: list[Camera], masks: list[np.ndarray],
                 rounds: tuple[tuple[float, float], ...] = CONSENSUS_ROUNDS,
                 resolution: int = CONSENSUS_RESOLUTION,
                 seeds: list[np.ndarray | None] | None = None,
                 support: tuple[np.ndarray, float] | None = None) -> tuple[list[np.ndarray], list[str]]:
    """The consensus rounds (module notes): the hull comes from every view's mask, and the views with an
    8-bit sRGB image (None: keep the mask, e.g. a keyed one) are cut again with their parallax `seeds` set: the
    background's everywhere, the object's half a matching window inside the projected hull (a seed reaches that far
    past the outline, which the band decides; inside, it keeps a part thinner than the band, a statue's head, from
    being left to colour alone). The hull is cut at the `support` plane (`consensus_outlines`). Returns the masks
    and each view's method ("grabcut", "consensus hull" where GrabCut lost the object, "kept")."""
    seeds = seeds or [None] * len(cameras)
    methods = ["grabcut" if image8 is not None else "kept" for image8 in images8]
    for fraction, band in rounds:
        votes = max(2, int(round(fraction * len(cameras))))
        try:
            outlines = consensus_outlines(cameras, masks, votes, resolution, support)
        except ValueError as exc:
            log.warning("consensus round skipped: %s", exc)
            break
        masks = list(masks)
        for i, (image8, outline) in enumerate(zip(images8, outlines)):
            if image8 is None:
                continue
            width = max(2, int(round(band * np.sqrt(outline.sum()))))
            kept = None if seeds[i] is None else np.where(
                (seeds[i] == OBJECT) & ~shrink(outline, PARAMS.window // 2), 0, seeds[i])
            masks[i] = clean_mask(grabcut(image8, with_seeds(band_prior(outline, width), kept),
                                          GRABCUT_ITERATIONS), FILL_HOLES_BELOW)
            methods[i] = "grabcut"
            if mask_iou(masks[i], outline) < 0.5:  # GrabCut lost the object: keep the views' consensus
                log.warning("%s: GrabCut disagrees with the consensus hull; using the hull's projection",
                            cameras[i].name)
                masks[i], methods[i] = clean_mask(outline, FILL_HOLES_BELOW), "consensus hull"
    return masks, methods


SEED_SIZE = 240
"""longer image side (px) the parallax seeds are matched at (upsampled to the masks' size)"""


def parallax_seeds(pictures: list[np.ndarray], cameras: list[Camera], centre: np.ndarray,
                   support: tuple[np.ndarray, float] | None = None) -> list[np.ndarray]:
    """Each view's parallax seeds (dpi.preprocess.depth_seeds; `centre`: the point the cameras look at; `support`: the
    plane the object stands on, depth_seeds.support_plane), matched at SEED_SIZE, each kind shrunk by half the matcher's
    window there (a window that straddles the outline matches both sides), at the pictures' size (nearest)."""
    height, width = pictures[0].shape[:2]
    small_w, small_h = working_size((width, height), SEED_SIZE)
    small = [camera.resized(small_w, small_h) for camera in cameras]
    greys = [grey(resize(torch.from_numpy(p), small_h, small_w).numpy(), PARAMS.blur_px) for p in pictures]
    out = []
    for seeds in depth_seeds(greys, small, centre, support):
        kept = np.zeros_like(seeds)
        for kind in (OBJECT, BACKGROUND):
            kept[shrink(seeds == kind, PARAMS.window // 2)] = kind
        rows, cols = np.arange(height) * small_h // height, np.arange(width) * small_w // width
        out.append(kept[rows][:, cols])
    return out


def mask_agreement(cameras: list[Camera], masks: list[np.ndarray], resolution: int,
                   support: tuple[np.ndarray, float] | None = None) -> list[float] | None:
    """Each view's IoU with the projection of the hull carved where AGREEMENT_VOTE_SHARE of the views see a voxel
    outside their masks, and below the `support` plane (None when no hull can be carved, e.g. masks that share no
    object)."""
    votes = max(2, int(round(AGREEMENT_VOTE_SHARE * len(cameras))))
    try:
        outlines = consensus_outlines(cameras, masks, votes, resolution, support)
    except ValueError as exc:
        log.warning("mask agreement not measured: %s", exc)
        return None
    return [mask_iou(mask, outline) for mask, outline in zip(masks, outlines)]


MIN_PARALLAX_PX = 2.0
"""least shift, in pixels at the working size, of a point at the scene's depth between the two farthest cameras:
below it the photos hold no parallax to tell the object from what lies behind it"""


def capture_geometry_problem(cameras: list[Camera], points: np.ndarray | None) -> str | None:
    """Why the views cannot give masks, from the capture's geometry alone (None: they can): fewer than
    MIN_DERIVED_VIEWS views with cameras, or cameras so close together that a point at the scene's depth (the sparse
    points' median distance) shifts by less than MIN_PARALLAX_PX between the farthest two (photos from one spot)."""
    if len(cameras) < MIN_DERIVED_VIEWS:
        return (f"only {len(cameras)} photo(s) have cameras: deriving masks takes {MIN_DERIVED_VIEWS} or more, taken "
                "from different places around the object (dozens for a good fit)")
    centres = np.stack([c.center for c in cameras])
    baseline = float(np.linalg.norm(centres[:, None] - centres[None], axis=-1).max())
    if points is None or len(points) == 0:
        if baseline > 0:
            return None
        return "every camera is at the same place: photos from one spot show no parallax; walk around the object"
    depth = float(np.median(np.linalg.norm(points[:, None] - centres[None], axis=-1)))
    shift = min(c.fx for c in cameras) * baseline / max(depth, 1e-12)
    if shift >= MIN_PARALLAX_PX:
        return None
    return (f"the cameras lie within {baseline:.3g} of each other, {depth:.3g} from the scene: a point there shifts by "
            f"{shift:.2g} px between the farthest two photos (photos from one spot show no parallax to tell the "
            "object from its background); walk around the object")


def derive_masks(images: dict[str, Path], cameras: dict[str, Camera], out_dir: str | Path,
                 cfg: MaskConfig | None = None, points: np.ndarray | None = None,
                 scene_points: np.ndarray | None = None) -> dict:
    """Write one mask PNG per view (out_dir/{view}.png) and return a summary (prior, method per view, areas).

    Views without a camera get no mask. `points`: the object's sparse points (N, 3), if any; `scene_points`: all of
    them (the parallax seeds find the support there)."""
    cfg = cfg or MaskConfig()
    from dpi.preprocess.segmenter import load_segmenter, weights_file

    if cfg.method not in METHODS:
        raise ValueError(f"mask method must be one of {', '.join(METHODS)}, got {cfg.method!r}")
    if cfg.method == "learned" and not cfg.weights:
        raise ValueError("preprocess.masks.method learned needs preprocess.masks.weights (the segmenter's file)")
    weights = weights_file(cfg.weights) if cfg.weights and cfg.method in ("auto", "learned") else None
    segmenter = load_segmenter(cfg.segmenter, weights) if weights else None
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    names = [n for n in images if n in cameras]
    pictures = [read_image(images[n]) for n in names]
    full = pictures[0].shape[1], pictures[0].shape[0]
    width, height = working_size(full, cfg.max_size)
    views = [cameras[n].resized(width, height) for n in names]
    problem = capture_geometry_problem(views, scene_points if scene_points is not None else points)
    if problem:
        raise CaptureError(f"{images[names[0]].parent if names else 'images/'}: {problem}")
    pictures = [resize(torch.from_numpy(p), height, width).numpy() for p in pictures]
    centre, radius = visible_sphere(views)
    sphere = (centre, SPHERE_FRACTION * radius)
    if points is not None:
        points = drop_outliers(points, OUTLIER_STD_RATIO)
    images8 = [to_uint8(picture) for picture in pictures]
    prompted = any(choose_method(image8, cfg, segmenter)[0] != "key" for image8 in images8)  # keying takes no seeds
    support = support_plane(views, centre, scene_points)
    seeds = parallax_seeds(pictures, views, centre, support) if cfg.parallax and prompted else [None] * len(views)
    first = [object_mask(picture, camera, cfg, sphere, points, segmenter, seed, scene_points)
             for picture, camera, seed in zip(pictures, views, seeds)]
    masks, methods = [m for m, _ in first], [method for _, method in first]
    use_points = points is not None and len(points) >= MIN_POINTS
    summary = {"views": {}, "prior": "sphere and sparse points" if use_points else "sphere", "consensus_rounds": 0,
               **({"segmenter": str(weights), "segmenter_kind": cfg.segmenter} if weights else {})}
    if "grabcut" in methods:
        to_cut = [image8 if method == "grabcut" else None for image8, method in zip(images8, methods)]
        refined, new_methods = refine_masks(to_cut, views, masks, seeds=seeds, support=support)
        masks = refined
        methods = [old if new == "kept" else new for old, new in zip(methods, new_methods)]
        summary["consensus_rounds"] = len(CONSENSUS_ROUNDS)
    agreement = mask_agreement(views, masks, CONSENSUS_RESOLUTION, support) if len(views) >= 3 else None
    floor = None if agreement is None else MASK_AGREEMENT * float(np.median(agreement))
    reasons = {}
    for i, (name, image8, camera, mask, method) in enumerate(zip(names, images8, views, masks, methods)):
        if not mask.any():
            cause = "check the capture or the mask settings" if use_points else WITHOUT_POINTS
            raise ValueError(f"{images[name]}: empty foreground mask ({method}); {cause}")
        view = {"method": method, "foreground_fraction": round(float(mask.mean()), 4)}
        for key, value in (("agreement", None if agreement is None else agreement[i]),
                           ("point_coverage", point_coverage(camera, mask, points)),
                           ("frame_contact", frame_contact(mask)),
                           ("edge_support", edge_support(image8, mask))):
            if value is not None:
                view[key] = round(value, 4)
        reasons[name] = verdict(view, floor)
        view["reliable"] = not reasons[name]
        if reasons[name]:
            view["why"] = "; ".join(reasons[name])
        summary["views"][name] = view
    if (width, height) != full:
        masks = [resize_mask(mask, *full) for mask in masks]
    for name, mask in zip(names, masks):
        write_mask(out_dir / f"{name}.png", mask)
    summary["unreliable"] = [n for n, why in reasons.items() if why]
    if summary["unreliable"]:
        log.warning("masks unreliable for %d of %d views; look at them before trusting a decomposition: %s",
                    len(summary["unreliable"]), len(names),
                    "; ".join(f"{n} ({summary['views'][n]['why']})" for n in summary["unreliable"]))
    return summary


