"""What the preprocessing stages share about a ring of cameras and the object's silhouettes: the
point the cameras look at, the sphere every camera sees whole, and the visual hull carved from masks.

**Carving.** Every view's mask gives a 2-D signed distance to the silhouette (pixels, negative
inside). A voxel projected into a view reads that distance, scaled to world units by its depth
over the focal length. The standard visual hull keeps a voxel when *no* view sees it outside,
i.e. it takes the maximum over views; here the field is the `outside_votes`-th largest value, so
a voxel is carved only when that many views agree, and one or two bad masks (a bite out of the
object) cannot carve the object away. A voxel outside a view's frame counts as seen outside by it
(the object is in every image), unless `in_frame` is off; then views that do not see a voxel do not
vote, and a voxel seen by fewer than `min_view_fraction` of the views is outside. A coarse pass over
the box around the point the cameras look at finds the object's extent; the fine pass carves that box.

Used by structure from motion (which points belong to the object), the masks (the consensus hull)
and the geometry stage (the surface); it imports none of them.
"""

from __future__ import annotations

import logging

import numpy as np

from dpi.capture.cameras import Camera

log = logging.getLogger(__name__)


def axes_centre(cameras: list[Camera]) -> np.ndarray:
    """Least-squares point nearest to every camera's optical axis (what a walk-around looks at)."""
    a, b = np.zeros((3, 3)), np.zeros(3)
    for cam in cameras:
        d = -cam.c2w[:3, 2] / np.linalg.norm(cam.c2w[:3, 2])
        p = np.eye(3) - np.outer(d, d)
        a += p
        b += p @ cam.center
    return np.linalg.lstsq(a, b, rcond=None)[0]


def visible_sphere(cameras: list[Camera]) -> tuple[np.ndarray, float]:
    """(centre, radius): the point the cameras look at and 90% of the largest sphere around it that
    lies inside every camera's field of view."""
    centre = axes_centre(cameras)
    radius = np.inf
    for cam in cameras:
        distance = np.linalg.norm(cam.center - centre)
        half = np.arctan(min(cam.width / (2 * cam.fx), cam.height / (2 * cam.fy)))
        radius = min(radius, distance * np.sin(half))
    return centre, 0.9 * float(radius)


def signed_distance_2d(mask: np.ndarray) -> np.ndarray:
    """Signed distance (h, w) in pixels to the silhouette boundary: negative inside, positive outside."""
    import cv2

    m = mask.astype(np.uint8)
    outside = cv2.distanceTransform(1 - m, cv2.DIST_L2, 5)
    inside = cv2.distanceTransform(m, cv2.DIST_L2, 5)
    bound = float(sum(mask.shape))  # an empty or full mask has no boundary: distances saturate
    return np.clip(np.where(mask, 0.5 - inside, outside - 0.5), -bound, bound).astype(np.float32)


def _sample(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear samples of an (h, w) float image at pixel positions (x, y) (pixel centres at +0.5)."""
    import cv2

    n = len(x)
    if n == 0:
        return np.zeros(0, np.float32)
    width = 4096
    rows = -(-n // width)
    mx = np.zeros(rows * width, np.float32)
    my = np.zeros(rows * width, np.float32)
    mx[:n], my[:n] = x - 0.5, y - 0.5
    out = cv2.remap(image, mx.reshape(rows, width), my.reshape(rows, width), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(-1)[:n]


def carve_points(cameras: list[Camera], distances: list[np.ndarray], points: np.ndarray, outside_votes: int = 2,
                 min_view_fraction: float = 0.5, far: float = 1.0, in_frame: bool = True) -> np.ndarray:
    """Carved signed distance (N,) at world points (N, 3): the `outside_votes`-th largest of the views'
    silhouette distances (world units, negative inside); `far` where too few views see a point.

    distances: each view's `signed_distance_2d` of its mask. in_frame: the object lies inside every
    image, so a point outside a view's frame (or behind it) is outside the object for that view."""
    points = np.asarray(points, np.float32)
    k = max(1, int(outside_votes))
    top = np.full((k, len(points)), -np.inf, np.float32)  # k largest per-view distances, descending
    seen = np.zeros(len(points), np.int32)
    for cam, sdf2d in zip(cameras, distances):
        w2c = np.linalg.inv(cam.c2w).astype(np.float32)
        p = points @ w2c[:3, :3].T + w2c[:3, 3]
        depth = -p[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = cam.fx * p[:, 0] / depth + cam.cx
            y = -cam.fy * p[:, 1] / depth + cam.cy
        valid = (depth > 1e-6) & (x >= 0) & (x < cam.width) & (y >= 0) & (y < cam.height)
        value = np.full(len(points), far if in_frame else -np.inf, np.float32)
        value[valid] = _sample(sdf2d, x[valid], y[valid]) * depth[valid] / cam.fx
        seen += valid | in_frame
        for j in range(k):  # insert into the sorted top-k
            larger = np.maximum(top[j], value)
            value = np.minimum(top[j], value)
            top[j] = larger
    field = top[k - 1]
    field[(seen < max(k, min_view_fraction * len(cameras))) | ~np.isfinite(field)] = far
    return field


def grid_points(lo: np.ndarray, hi: np.ndarray, resolution: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Voxel centres (nx, ny, nz, 3) covering [lo, hi] with `resolution` voxels along the longest side,
    the centre of voxel (0, 0, 0) and the voxel size."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    size = float((hi - lo).max() / resolution)
    shape = np.maximum(np.ceil((hi - lo) / size).astype(int), 2)
    axes = [lo[i] + (np.arange(shape[i]) + 0.5) * size for i in range(3)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1), np.array([a[0] for a in axes]), size


def carve(cameras: list[Camera], distances: list[np.ndarray], lo: np.ndarray, hi: np.ndarray, resolution: int,
          outside_votes: int = 2, min_view_fraction: float = 0.5,
          in_frame: bool = True) -> tuple[np.ndarray, np.ndarray, float]:
    """Carved signed-distance field (nx, ny, nz) over the box [lo, hi], negative inside, its origin
    (centre of voxel 0) and voxel size.

    Two levels: the field at half the resolution, then exact values only in a band around its zero
    level set (elsewhere the coarse field, interpolated, has the right sign and is never meshed)."""
    from scipy.ndimage import map_coordinates

    grid, origin, size = grid_points(lo, hi, resolution)
    half, half_origin, half_size = grid_points(lo, hi, max(2, resolution // 2))
    far = 4 * half_size
    coarse = carve_points(cameras, distances, half.reshape(-1, 3), outside_votes, min_view_fraction,
                          far, in_frame).reshape(half.shape[:3])
    index = (grid.reshape(-1, 3) - half_origin) / half_size
    field = map_coordinates(coarse, index.T, order=1, mode="nearest").astype(np.float32)
    band = np.abs(field) < 2.0 * half_size
    field[band] = carve_points(cameras, distances, grid.reshape(-1, 3)[band], outside_votes, min_view_fraction, far,
                               in_frame)
    return field.reshape(grid.shape[:3]), origin, size


def search_box(cameras: list[Camera]) -> tuple[np.ndarray, np.ndarray]:
    """Box around the point the cameras look at, twice the largest sphere every camera sees whole."""
    centre, radius = visible_sphere(cameras)
    half = 2.0 * radius / 0.9
    return centre - half, centre + half


def visual_hull(cameras: list[Camera], masks: list[np.ndarray], resolution: int, coarse_resolution: int = 48,
                outside_votes: int = 2, min_view_fraction: float = 0.5, in_frame: bool = True,
                margin: float = 0.08) -> tuple[np.ndarray, np.ndarray, float, dict]:
    """Carved field (negative inside) over the object's box, its origin and voxel size, and the box found.

    A coarse pass over the search box finds the object's extent; the fine pass carves that box (grown
    by `margin` of its size) with `resolution` voxels along its longest side."""
    distances = [signed_distance_2d(m) for m in masks]
    lo, hi = search_box(cameras)
    coarse, origin, size = carve(cameras, distances, lo, hi, coarse_resolution, outside_votes, min_view_fraction,
                                 in_frame)
    inside = np.argwhere(coarse < 0)
    if not len(inside):
        raise ValueError("carving left no voxel inside every silhouette (masks and cameras disagree)")
    box_lo = origin + (inside.min(0) - 1) * size
    box_hi = origin + (inside.max(0) + 1) * size
    pad = margin * (box_hi - box_lo).max()
    box_lo, box_hi = box_lo - pad, box_hi + pad
    touches = bool((inside.min(0) == 0).any() or (inside.max(0) == np.array(coarse.shape) - 1).any())
    if touches:
        log.warning("the carved object touches the search box: cameras may not keep the whole object in view")
    field, origin, size = carve(cameras, distances, box_lo, box_hi, resolution, outside_votes, min_view_fraction,
                                in_frame)
    return field, origin, size, {"box": [box_lo.tolist(), box_hi.tolist()], "touches_search_box": touches}


def marching_cubes(field: np.ndarray, origin: np.ndarray, size: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of the zero level set of a field (padded, so the surface is closed)."""
    from skimage.measure import marching_cubes as mc

    padded = np.pad(field, 1, constant_values=max(float(field.max()), size))
    if padded.min() >= 0:
        raise ValueError("carving left no voxel inside every silhouette (masks and cameras disagree)")
    verts, faces, _, _ = mc(padded, 0.0, spacing=(size, size, size))
    return verts + origin - size, faces.astype(np.int64)


def up_direction(cameras: list[Camera]) -> np.ndarray:
    """World up as the cameras hold it: the mean of their image-up axes (photos are taken level)."""
    up = np.mean([cam.c2w[:3, 1] for cam in cameras], axis=0)
    return up / np.linalg.norm(up)


def rim_heights(cameras: list[Camera], masks: list[np.ndarray], field: np.ndarray, origin: np.ndarray,
                size: float, up: np.ndarray, samples: int = 2000) -> list[float]:
    """Per view, the height along `up` of the point where its lowest silhouette ray first touches the
    carved hull (seen from the camera); views whose ray misses the hull by more than a voxel have none.

    The ray through a silhouette's lowest pixel touches the object at its rim; where cameras look only
    from above, that is the object's footing: exact for a flat base, r (1 - cos a) above the contact
    for a round bottom met by a ray a below the horizon. Past the touch the ray runs on along the
    hull's underside, the cone no view carves, so its lowest point there would sink a flat base's
    plane by up to r tan a."""
    from scipy.ndimage import map_coordinates

    centre = origin + (np.array(field.shape) - 1) * size / 2
    span = float(np.linalg.norm(np.array(field.shape) * size))
    heights = []
    for cam, mask in zip(cameras, masks):
        ys, xs = np.nonzero(mask)
        if not len(xs):
            continue
        w2c = np.linalg.inv(cam.c2w)

        def project(p: np.ndarray) -> np.ndarray:
            q = w2c[:3, :3] @ p + w2c[:3, 3]
            return np.array([cam.fx * q[0], -cam.fy * q[1]]) / -q[2] + np.array([cam.cx, cam.cy])

        image_up = project(centre + 0.01 * span * up) - project(centre)
        k = int(np.argmin((xs + 0.5) * image_up[0] + (ys + 0.5) * image_up[1]))
        ray = cam.c2w[:3, :3] @ np.array([(xs[k] + 0.5 - cam.cx) / cam.fx, -(ys[k] + 0.5 - cam.cy) / cam.fy, -1.0])
        ray /= np.linalg.norm(ray)
        reach = float(np.linalg.norm(cam.center - centre))
        points = cam.center + np.linspace(reach - span, reach + span, samples)[:, None] * ray
        values = map_coordinates(field, ((points - origin) / size).T, order=1, mode="nearest")
        if values.min() > size:  # the ray misses the hull: this mask's bottom disagrees with the others
            continue
        first = np.flatnonzero(values <= values.min() + 0.5 * size)[0]
        while first + 1 < len(values) and values[first + 1] < values[first]:  # on to the first local minimum
            first += 1
        heights.append(float(points[first] @ up))
    return heights


def seen_from_above(cameras: list[Camera], field: np.ndarray, origin: np.ndarray, size: float,
                    min_elevation_deg: float = 5.0) -> np.ndarray | None:
    """World up (`up_direction`) when every camera looks at the carved object's centre from at least
    `min_elevation_deg` above it (no view sees its underside, every view sees the ground); None otherwise."""
    up = up_direction(cameras)
    inside = np.argwhere(field < 0)
    if not len(inside):
        return None
    centre = origin + inside.mean(0) * size
    offsets = np.array([cam.center - centre for cam in cameras])
    elevations = np.degrees(np.arcsin(np.clip(offsets @ up / np.linalg.norm(offsets, axis=1), -1, 1)))
    return up if elevations.min() >= min_elevation_deg else None


def support_plane(cameras: list[Camera], masks: list[np.ndarray], field: np.ndarray, origin: np.ndarray, size: float,
                  min_elevation_deg: float = 5.0, quantile: float = 0.1) -> tuple[np.ndarray, float] | None:
    """(up, height) of the plane the object stands on when every camera looks at it from above (at least
    `min_elevation_deg` over its centre), so no view sees its underside; None otherwise.

    The height is the `quantile` of the views' `rim_heights` (0: the lowest): a few masks that take a
    strip of the ground for the object do not sink the plane."""
    up = seen_from_above(cameras, field, origin, size, min_elevation_deg)
    if up is None:
        return None
    heights = rim_heights(cameras, masks, field, origin, size, up)
    if not heights:
        return None
    return up, float(np.quantile(heights, quantile, method="lower"))


def cut_below(field: np.ndarray, origin: np.ndarray, size: float, up: np.ndarray, height: float) -> np.ndarray:
    """The field with everything below the plane {x . up = height} outside (a signed-distance union)."""
    x, y, z = (origin[i] + np.arange(n) * size for i, n in enumerate(field.shape))
    heights = x[:, None, None] * up[0] + y[None, :, None] * up[1] + z[None, None, :] * up[2]
    return np.maximum(field, (height - heights).astype(field.dtype))
