"""A watertight surface from masks and cameras: a voxel signed-distance field carved from the
silhouettes, its zero level set, and a mesh clean-up chain.

**Carving.** Every view's mask gives a 2-D signed distance to the silhouette (pixels, negative
inside). A voxel projected into a view reads that distance, scaled to world units by its depth
over the focal length. The standard visual hull keeps a voxel when *no* view sees it outside,
i.e. it takes the maximum over views; here the field is the `outside_votes`-th largest value, so
a voxel is carved only when that many views agree, and one or two bad masks (a bite out of the
object) cannot carve the object away. A voxel outside a view's frame counts as seen outside by it (the object is in every image), unless
`object_in_frame` is off; then views that do not see a voxel do not vote, and a voxel seen by
fewer than `min_view_fraction` of the views is outside. A coarse pass over the box
around the point the cameras look at finds the object's extent; the fine pass carves that box.

**Surface.** Marching cubes (scikit-image) extracts the zero level set; pymeshlab then removes
small components, repairs non-manifold edges and vertices, closes holes, applies Taubin
smoothing (no shrinkage), decimates to a face budget and remeshes isotropically. The result is
oriented outwards (positive volume), as Mitsuba's one-sided BSDFs need.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dpi.cameras import Camera

log = logging.getLogger(__name__)


@dataclass
class GeometryConfig:
    """Settings of carving and mesh clean-up."""

    resolution: int = 128
    """voxels along the longest side of the object's box (fine pass)"""
    coarse_resolution: int = 48
    """voxels along the side of the search box (coarse pass)"""
    outside_votes: int = 2
    """views that must see a voxel outside its silhouette to carve it (tolerates outside_votes - 1 bad masks)"""
    object_in_frame: bool = True
    """the whole object is inside every image: a voxel outside a view's frame is outside the object"""
    min_view_fraction: float = 0.5
    """without object_in_frame: a voxel inside fewer than this fraction of the views' frames is outside"""
    margin: float = 0.08
    """margin around the coarse hull's box, as a fraction of its size"""
    smoothing_steps: int = 10
    """Taubin smoothing iterations"""
    target_faces: int = 20000
    """face budget of the decimated mesh"""
    remesh_iterations: int = 3
    """isotropic remeshing iterations (0: none)"""
    remesh_edge: float | None = None
    """target edge length of the remeshing, percent of the bounding-box diagonal (None: the length
    whose equilateral triangles keep the face budget)"""
    min_component: float = 20.0
    """components with a diagonal below this percent of the whole are removed"""


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
    from dpi.preprocess.masks import visible_sphere

    centre, radius = visible_sphere(cameras)
    half = 2.0 * radius / 0.9
    return centre - half, centre + half


def marching_cubes(field: np.ndarray, origin: np.ndarray, size: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of the zero level set of a field (padded, so the surface is closed)."""
    from skimage.measure import marching_cubes as mc

    padded = np.pad(field, 1, constant_values=max(float(field.max()), size))
    if padded.min() >= 0:
        raise ValueError("carving left no voxel inside every silhouette (masks and cameras disagree)")
    verts, faces, _, _ = mc(padded, 0.0, spacing=(size, size, size))
    return verts + origin - size, faces.astype(np.int64)


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Volume enclosed by a closed triangle mesh; negative when its faces point inwards."""
    v = vertices[faces]
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6)


def clean_mesh(vertices: np.ndarray, faces: np.ndarray, cfg: GeometryConfig) -> tuple[np.ndarray, np.ndarray]:
    """pymeshlab chain: small components, non-manifold repair, holes, Taubin smoothing, decimation, remeshing."""
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices.astype(np.float64), face_matrix=faces.astype(np.int32)))
    ms.meshing_remove_duplicate_vertices()
    ms.meshing_remove_connected_component_by_diameter(mincomponentdiag=pymeshlab.PercentageValue(cfg.min_component))
    ms.meshing_repair_non_manifold_edges()
    ms.meshing_repair_non_manifold_vertices()
    ms.meshing_close_holes(maxholesize=100)
    if cfg.smoothing_steps:
        ms.apply_coord_taubin_smoothing(stepsmoothnum=cfg.smoothing_steps)
    if ms.current_mesh().face_number() > cfg.target_faces:
        ms.meshing_decimation_quadric_edge_collapse(targetfacenum=cfg.target_faces, preservenormal=True,
                                                    preservetopology=True, optimalplacement=True)
    if cfg.remesh_iterations:
        if cfg.remesh_edge is None:
            area = ms.get_geometric_measures()["surface_area"]
            target = pymeshlab.PureValue(float(np.sqrt(4 * area / (np.sqrt(3) * cfg.target_faces))))
        else:
            target = pymeshlab.PercentageValue(cfg.remesh_edge)
        ms.meshing_isotropic_explicit_remeshing(iterations=cfg.remesh_iterations, targetlen=target)
    ms.meshing_repair_non_manifold_edges()
    ms.meshing_remove_unreferenced_vertices()
    mesh = ms.current_mesh()
    vertices, faces = mesh.vertex_matrix().copy(), mesh.face_matrix().astype(np.int64).copy()
    if signed_volume(vertices, faces) < 0:
        faces = faces[:, ::-1].copy()
    return vertices, faces


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


def reconstruct_surface(cameras: list[Camera], masks: list[np.ndarray],
                        cfg: GeometryConfig | None = None) -> tuple[np.ndarray, np.ndarray, dict]:
    """Watertight mesh (vertices, faces) of the object seen in the masks, and a summary with timings."""
    cfg = cfg or GeometryConfig()
    times = {}
    start = time.perf_counter()
    field, origin, size, box = visual_hull(cameras, masks, cfg.resolution, cfg.coarse_resolution, cfg.outside_votes,
                                           cfg.min_view_fraction, cfg.object_in_frame, cfg.margin)
    times["carve_s"] = time.perf_counter() - start
    start = time.perf_counter()
    vertices, faces = marching_cubes(field, origin, size)
    times["marching_cubes_s"] = time.perf_counter() - start
    start = time.perf_counter()
    vertices, faces = clean_mesh(vertices, faces, cfg)
    times["cleanup_s"] = time.perf_counter() - start
    summary = {**box, "voxel_size": size, "grid": list(field.shape), "vertices": len(vertices), "faces": len(faces),
               **{k: round(v, 3) for k, v in times.items()}}
    return vertices, faces, summary


def write_mesh_ply(path: str | Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    """A mesh without UVs as a binary PLY (written by trimesh, atomically)."""
    import trimesh

    from dpi.atomic import atomic_path

    with atomic_path(path) as tmp:
        trimesh.Trimesh(vertices, faces, process=False).export(tmp, file_type="ply")


def read_mesh(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) of a PLY/OBJ mesh (trimesh, vertices not merged)."""
    import trimesh

    mesh = trimesh.load(path, force="mesh", process=False)
    return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)
