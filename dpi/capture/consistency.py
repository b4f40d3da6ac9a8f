"""Whether the cameras agree with the images: the mesh's silhouette per camera against each view's mask.

A camera list in another convention (OpenCV's camera looks down +z with y down; dpi's, OpenGL's, looks
down -z with y up), in another scale than the mesh, or matched to the images in another order still
validates camera by camera, and the whole fit then explains views the mesh does not project into.
Comparing what each camera sees of the mesh with the view's mask catches all three. Silhouettes are
ray cast (open3d) through the pixel centres of each camera at CHECK_SIZE px, the masks are resampled
to the same size, and their intersection over union (IoU) is compared:

- a view fails when its IoU is below MIN_IOU; and the list fails when most views fit the camera given
  for another view (a cyclic shift of the list) better than their own: a shifted list of a near-symmetric
  object keeps every IoU high (a blob's neighbouring views overlap with IoU 0.95);
- without masks, a view fails when less than MIN_INSIDE of the mesh's vertices project into the image
  from in front of the camera.

On failure the likely cause is named: the convention (the OpenCV flip is tried), the order (another
camera of the list fits the view), or the scale (the silhouette's size against the mask's).
"""

from __future__ import annotations

import math

import numpy as np

from dpi.capture.cameras import Camera, centre_rays
from dpi.io.images import resize_mask, working_size

CHECK_SIZE = 64
"""longer side (px) of the silhouettes and masks compared"""
MIN_IOU = 0.7
"""a view whose silhouette overlaps its mask less than this fails (synthetic captures: >= 0.96)"""
ORDER_MAJORITY = 0.75
"""the camera list is out of order when this fraction of the views fits a shifted list better ..."""
ORDER_MARGIN = 0.01
"""... and the shifted list's mean IoU exceeds the given one's by more than this"""
MIN_INSIDE = 0.5
"""without masks, a view fails when less than this fraction of the mesh's vertices projects into the image"""
MAX_VERTICES = 20_000
"""vertices projected per view (a larger mesh is subsampled evenly)"""
SCALE_TOLERANCE = 1.25
"""a silhouette this many times larger or smaller (linear size) than the mask names the scale as cause"""
OPENCV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])
"""an OpenCV camera-to-world matrix times this is the OpenGL one (and back)"""
LISTED_VIEWS = 6
"""views named in a message before the rest is counted"""


def raycasting_scene(vertices: np.ndarray, faces: np.ndarray):
    """An open3d RaycastingScene of a triangle mesh."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(vertices, np.float32)), o3d.core.Tensor(np.asarray(faces, np.uint32)))
    return scene


def silhouette(scene, camera: Camera) -> np.ndarray:
    """Whether the ray through each pixel centre of `camera` hits the mesh of `scene`, (h, w) bool."""
    import open3d as o3d

    return scene.test_occlusions(o3d.core.Tensor(centre_rays(camera))).numpy().reshape(camera.height, camera.width)


def padded(camera: Camera) -> Camera:
    """The camera with its frame extended by the image's size on every side (3x wider and higher)."""
    return Camera(camera.c2w, 3 * camera.width, 3 * camera.height, camera.fx, camera.fy,
                  camera.cx + camera.width, camera.cy + camera.height, camera.name)


def overlaps(masks: np.ndarray, silhouettes: np.ndarray) -> np.ndarray:
    """IoU (n, m) of every mask (n, h, w) with every silhouette (m, h, w); 1 where both are empty."""
    a = masks.reshape(len(masks), -1).astype(np.float32)
    b = silhouettes.reshape(len(silhouettes), -1).astype(np.float32)
    both = a @ b.T
    union = a.sum(1)[:, None] + b.sum(1)[None, :] - both
    return np.where(union > 0, both / np.maximum(union, 1), 1.0)


def mask_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two boolean masks (1 when both are empty)."""
    return float(overlaps(a[None], b[None])[0, 0])


def silhouettes(scene, cameras: list[Camera]) -> np.ndarray:
    """The mesh's silhouettes (n, h, w) from `cameras` (all of one size)."""
    return np.stack([silhouette(scene, camera) for camera in cameras])


def inside_fraction(vertices: np.ndarray, camera: Camera) -> float:
    """Fraction of the vertices that lie in front of `camera` and project into its image."""
    with np.errstate(divide="ignore", invalid="ignore"):  # a vertex in the camera's plane projects to infinity
        pixels, depth = camera.project(vertices)
    inside = (depth > 0) & (pixels >= 0).all(1) & (pixels[:, 0] <= camera.width) & (pixels[:, 1] <= camera.height)
    return float(inside.mean())


def check_cameras(cameras: list[Camera]) -> list[Camera]:
    """The cameras resized to the check size (longer side at most CHECK_SIZE)."""
    return [c.resized(*working_size((c.width, c.height), CHECK_SIZE)) for c in cameras]


def check_masks(masks: list[np.ndarray], size: tuple[int, int]) -> np.ndarray:
    """The masks (n, h, w) resampled to size (width, height)."""
    return np.stack([resize_mask(m, *size) for m in masks])


def preferred_shift(table: np.ndarray) -> int | None:
    """The cyclic shift s of the camera list (view i taking the camera given for view i + s) that fits the
    masks better than the list as given (in ORDER_MAJORITY of the views, by ORDER_MARGIN on average), or None."""
    n = len(table)
    own, gains = np.diag(table), {}
    for s in range(1, n):
        other = table[np.arange(n), (np.arange(n) + s) % n]
        if (other > own).mean() >= ORDER_MAJORITY and (other - own).mean() > ORDER_MARGIN:
            gains[s] = (other - own).mean()
    return max(gains, key=gains.get) if gains else None


def listed(names: list[str], values: np.ndarray, indices: np.ndarray) -> str:
    """'r_0 0.00, r_1 0.12, ..., and 4 more': the first LISTED_VIEWS views with their values."""
    shown = ", ".join(f"{names[i]} {values[i]:.2f}" for i in indices[:LISTED_VIEWS])
    more = len(indices) - LISTED_VIEWS
    return shown + (f", and {more} more" if more > 0 else "")


def flipped(cameras: list[Camera]) -> list[Camera]:
    """The cameras with their matrices read in the other convention (OpenCV <-> OpenGL)."""
    return [Camera(c.c2w @ OPENCV_TO_GL, c.width, c.height, c.fx, c.fy, c.cx, c.cy, c.name) for c in cameras]


CONVENTION = ("convention: the poses are OpenCV's (camera looking down +z, y down) where dpi reads OpenGL's "
              "(looking down -z, y up); with every camera-to-world matrix times diag(1, -1, -1, 1)")


def shift_cause(table: np.ndarray, names: list[str], shift: int) -> str:
    """The order as cause: the list fits shifted by `shift`, with the first view's numbers."""
    n = len(names)
    other = table[np.arange(n), (np.arange(n) + shift) % n]
    signed = shift if shift <= n // 2 else shift - n
    return (f"order: the camera list is shifted by {signed:+d} against the images ({names[0]}'s mask fits the "
            f"camera given for {names[shift]}, IoU {other[0]:.2f}; shifted, the views fit with mean IoU "
            f"{other.mean():.2f}, as given {np.diag(table).mean():.2f})")


FOV_RANGE_DEG = (1.0, 170.0)
"""horizontal fields of view a camera of an object capture can have; outside them the focal length is wrong"""


def intrinsics_cause(cameras: list[Camera], names: list[str]) -> str | None:
    """A camera whose own intrinsics cannot be right (a field of view outside FOV_RANGE_DEG, a principal point
    outside its image), named with its numbers, or None."""
    for camera, name in zip(cameras, names):
        fov = math.degrees(2 * math.atan(camera.width / (2 * camera.fx)))
        if not FOV_RANGE_DEG[0] <= fov <= FOV_RANGE_DEG[1]:
            return (f"focal length: {name}'s fl_x {camera.fx:g} px gives a {fov:.3g} deg field of view on its "
                    f"{camera.width} px wide image (expected {FOV_RANGE_DEG[0]:g}-{FOV_RANGE_DEG[1]:g} deg)")
        if not (0 <= camera.cx <= camera.width and 0 <= camera.cy <= camera.height):
            return (f"principal point: {name}'s (cx, cy) = ({camera.cx:g}, {camera.cy:g}) lies outside its "
                    f"{camera.width}x{camera.height} image")
    return None


def focal_cause(cameras: list[Camera], names: list[str], bad: np.ndarray) -> str | None:
    """Where the views that contradict their masks share a field of view that none of the views that fit has (a
    split or a file of frames with its own, wrong intrinsics), that cause named with both fields of view; else None."""
    good = np.setdiff1d(np.arange(len(cameras)), bad)
    if not len(good):
        return None
    fov = np.array([math.degrees(2 * math.atan(c.width / (2 * c.fx))) for c in cameras])
    if np.ptp(fov[bad]) > 1e-3 * fov[bad].mean() or np.abs(fov[good] - fov[bad][0]).min() <= 1e-3 * fov[bad][0]:
        return None
    return (f"focal length: the views that contradict their masks ({names[bad[0]]}, ...) have a {fov[bad][0]:.3g} "
            f"deg field of view, the views that fit {fov[good][0]:.3g} deg: their intrinsics are wrong (a split or "
            "file of frames with its own camera_angle_x or fl_x?)")


def extent(points: np.ndarray) -> float:
    """Diagonal of the bounding box of pixel positions (n, 2); 0 for none."""
    return float(np.linalg.norm(points.max(0) - points.min(0))) if len(points) else 0.0


def projected_extent(vertices: np.ndarray, camera: Camera) -> float | None:
    """The diagonal (pixels) of the box of the vertices a camera sees in front of it within its padded frame, or
    None when it sees none."""
    with np.errstate(divide="ignore", invalid="ignore"):
        pixels, depth = camera.project(vertices)
    frame = np.array([camera.width, camera.height])
    seen = (depth > 0) & (pixels >= -frame).all(1) & (pixels <= 2 * frame).all(1)
    return extent(pixels[seen]) if seen.any() else None


def offset_from_mask(vertices: np.ndarray, camera: Camera, mask: np.ndarray) -> float | None:
    """How far the centre of the vertices a camera sees in front of it lies from the mask's centre, in units of the
    mask's size (diagonal); None when the camera sees no vertex in front of it (or the mask is empty). Meshes in
    other units project around the mask's centre (near 0); a mesh in another place projects elsewhere."""
    with np.errstate(divide="ignore", invalid="ignore"):
        pixels, depth = camera.project(vertices)
    ahead = pixels[depth > 0]
    points = np.argwhere(mask)[:, ::-1] * np.array([camera.width / mask.shape[1], camera.height / mask.shape[0]])
    if not len(ahead) or not len(points):
        return None
    return float(np.linalg.norm(ahead.mean(0) - points.mean(0)) / max(extent(points), 1.0))


def mask_cause(scene, vertices: np.ndarray, cameras: list[Camera], masks: np.ndarray, table: np.ndarray,
               names: list[str], bad: np.ndarray) -> str:
    """The likely cause of views whose silhouettes contradict their masks: the intrinsics, inverted masks, the
    convention, the order, the scale, or mismatched files."""
    inverted = np.diag(overlaps(~masks, silhouettes(scene, cameras)))
    if (inverted[bad] >= MIN_IOU).all():
        return (f"mask polarity: the masks fit inverted (IoU >= {inverted[bad].min():.2f}): a mask is white "
                "(255) on the object and black (0) elsewhere")
    flip = np.diag(overlaps(masks, silhouettes(scene, flipped(cameras))))
    if (flip >= MIN_IOU).all():
        return f"{CONVENTION} every view fits (IoU >= {flip.min():.2f})"
    shift = preferred_shift(table)
    if shift is not None:
        return shift_cause(table, names, shift)
    focal = focal_cause(cameras, names, bad)
    if focal:
        return focal
    best = table.argmax(1)
    swapped = [i for i in bad if best[i] != i and table[i, best[i]] >= MIN_IOU]
    if swapped:
        i = swapped[0]
        return (f"order: cameras and images are matched in another order ({names[i]}'s mask fits the camera given "
                f"for {names[best[i]]}, IoU {table[i, best[i]]:.2f})")
    vertices = np.asarray(vertices)[::math.ceil(len(vertices) / MAX_VERTICES)]
    off = [offset_from_mask(vertices, cameras[i], masks[i]) for i in bad]
    if sum(o is None or o > 1.0 for o in off) > len(bad) / 2:
        return ("placement: the mesh lies behind the cameras or away from the object they show (it projects outside "
                "the masks in most of those views): the mesh and the cameras are in different frames (mismatched "
                "files, or a mesh moved after the capture)")
    area = np.array([silhouette(scene, padded(cameras[i])).sum() for i in bad])  # the part outside the image too
    if area.any():
        ratio = float(np.median(np.sqrt(area / np.maximum(masks[bad].sum((1, 2)), 1))))
    else:  # smaller than a pixel, or out of sight: the projected vertices tell which
        seen = [(projected_extent(vertices, cameras[i]), extent(np.argwhere(masks[i])[:, ::-1])) for i in bad]
        seen = [(size, mask) for size, mask in seen if size]
        if not seen:
            return ("placement: no camera sees the mesh, not even just outside its image: the mesh and the cameras "
                    "are in different frames (mismatched files, or a mesh moved after the capture)")
        ratio = float(np.median([size / max(mask, 1.0) for size, mask in seen]))
    if not 1 / SCALE_TOLERANCE <= ratio <= SCALE_TOLERANCE:
        return (f"scale: the mesh's silhouette is {ratio:.2g}x the mask's size (median over those views): the mesh "
                f"and the cameras are in different units or scales{unit_hint(ratio)}")
    return "the mesh, the cameras and the masks do not show one object from the same places (mismatched files?)"


UNIT_RATIOS = {10.0: "centimetres against millimetres, or metres against decimetres", 100.0: "centimetres against "
               "metres", 1000.0: "millimetres against metres"}
"""size ratios that are a change of units, and which"""


def unit_hint(ratio: float) -> str:
    """A note naming the units a size ratio (either way) is the change of, within 15 %, or ''."""
    for factor, units in UNIT_RATIOS.items():
        for value in (factor, 1 / factor):
            if abs(math.log(ratio / value)) < math.log(1.15):
                return f" (about {ratio:.3g}x: {units}?)"
    return ""


def back_facing_fraction(vertices: np.ndarray, faces: np.ndarray, cameras: list[Camera]) -> float:
    """The fraction of the mesh the cameras see (rays through CHECK_SIZE px frames) whose faces point away from
    them: near 1 for a mesh whose faces are wound inwards (normals facing in), which renders dark."""
    import open3d as o3d

    scene = raycasting_scene(vertices, faces)
    away, hits = 0, 0
    for camera in check_cameras(cameras):
        rays = centre_rays(camera)
        cast = scene.cast_rays(o3d.core.Tensor(rays))
        hit = np.isfinite(cast["t_hit"].numpy())
        normals = cast["primitive_normals"].numpy()[hit]
        away += int(((normals * rays[hit, 3:]).sum(1) > 0).sum())
        hits += int(hit.sum())
    return away / hits if hits else 0.0


def masks_problem(scene, vertices: np.ndarray, cameras: list[Camera], masks: list[np.ndarray],
                  names: list[str]) -> str | None:
    """Why the cameras contradict the masks (views, IoUs, likely cause), or None."""
    small = check_cameras(cameras)
    masks = check_masks(masks, (small[0].width, small[0].height))
    table = overlaps(masks, silhouettes(scene, small))
    own = np.diag(table)
    bad = np.flatnonzero(own < MIN_IOU)
    if len(bad):
        return (f"the cameras contradict the masks: the mesh's silhouette overlaps the mask with IoU < {MIN_IOU:g} in "
                f"{len(bad)} of {len(names)} views ({listed(names, own, bad)}); likely cause: "
                + (intrinsics_cause(cameras, names) or mask_cause(scene, vertices, small, masks, table, names, bad)))
    shift = preferred_shift(table)
    if shift is None:
        return None
    n = len(names)
    better = np.flatnonzero(table[np.arange(n), (np.arange(n) + shift) % n] > own)
    return (f"the cameras contradict the masks: in {len(better)} of {n} views the mask fits another view's camera "
            f"better than its own (IoU with its own: {listed(names, own, better)}); likely cause: "
            + shift_cause(table, names, shift))


def frame_problem(vertices: np.ndarray, cameras: list[Camera], names: list[str]) -> str | None:
    """Why the mesh does not project into the images (views, fraction inside, likely cause), or None."""
    vertices = np.asarray(vertices)[::math.ceil(len(vertices) / MAX_VERTICES)]
    inside = np.array([inside_fraction(vertices, c) for c in cameras])
    bad = np.flatnonzero(inside < MIN_INSIDE)
    if not len(bad):
        return None
    flip = np.array([inside_fraction(vertices, c) for c in flipped(cameras)])
    cause = intrinsics_cause(cameras, names) or (f"{CONVENTION} the mesh lies in every image (at least {100 * flip.min():.0f}% of its vertices)"
             if (flip >= MIN_INSIDE).all() else
             "placement: no camera sees any of the mesh, so the mesh and the cameras are in different frames "
             "(mismatched files, or a mesh moved after the capture)" if not inside.any() else
             "the mesh and the cameras are in different frames or scales (mismatched files?)")
    return (f"the cameras do not see the mesh: less than {100 * MIN_INSIDE:.0f}% of its vertices project into the "
            f"image in {len(bad)} of {len(names)} views (fraction inside: {listed(names, inside, bad)}); "
            f"likely cause: {cause}")


def cameras_problem(vertices: np.ndarray, faces: np.ndarray, cameras: list[Camera],
                    masks: list[np.ndarray] | None, names: list[str]) -> str | None:
    """Why the cameras contradict the mesh and the masks (or, without masks, the image frames), or None."""
    if masks is None:
        return frame_problem(vertices, cameras, names)
    return masks_problem(raycasting_scene(vertices, faces), vertices, cameras, masks, names)
