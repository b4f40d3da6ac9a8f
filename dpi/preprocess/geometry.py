"""A watertight surface from masks and cameras: the visual hull carved from the silhouettes
(dpi.preprocess.hull), carved once more after the masks lost the ground they took
(dpi.preprocess.ground), carved further by multi-view stereo where the photos see empty space
inside it (dpi.preprocess.stereo), its zero level set, and a mesh clean-up chain.

**Surface.** Marching cubes (scikit-image) extracts the zero level set; pymeshlab then removes
small components, repairs non-manifold edges and vertices, closes holes, applies Taubin
smoothing (no shrinkage), decimates to a face budget and remeshes isotropically. The result is
oriented outwards (positive volume), as Mitsuba's one-sided BSDFs need.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import numpy as np
from pydantic import Field

from dpi.capture.cameras import Camera
from dpi.io.settings import Count, Steps, settings
from dpi.preprocess.hull import cut_below, marching_cubes, seen_from_above, support_plane, visual_hull

if TYPE_CHECKING:
    from dpi.preprocess.stereo import StereoParams

COARSE_RESOLUTION = 48
"""voxels along the side of the search box (the hull's coarse pass)"""
MIN_COMPONENT = 20.0
"""components with a diagonal below this percent of the whole are removed"""
OBJECT_IN_FRAME = True
"""the whole object is inside every image: a voxel outside a view's frame is outside the object"""
NEXT_PASS_FROM = 0.02
"""stereo's next pass runs only where the last one opened a concavity, removing at least this fraction of the
hull's voxels: on a convex object (a first pass trims about 1 % of a hull from 32 views) a further pass costs as
much again for nothing (notebook/log.md, "Preprocessing accuracy")"""
PHOTO_SIZE = 480
"""longer side (px) of the photos the ground test and stereo match: larger ones are area-downsampled,
cameras and masks follow (their windows are in pixels and their cost grows with the pixels; None:
the photos' own size). The silhouettes carve at full size"""
REMESH_EDGE = None
"""target edge length of the remeshing, percent of the bounding-box diagonal (None: the length
whose equilateral triangles keep the face budget)"""
SMOOTHING_STEPS = 10
"""Taubin smoothing iterations"""


@settings
class GeometryConfig:
    """Settings of carving and mesh clean-up."""

    resolution: Annotated[int, Field(ge=8, le=1024)] = 128
    """voxels along the longest side of the object's box (fine pass)"""
    outside_votes: Steps = 2
    """views that must see a voxel outside its silhouette to carve it (tolerates outside_votes - 1 bad masks)"""
    target_faces: Count = 20000
    """face budget of the decimated mesh"""
    remesh_iterations: Steps = 3
    """isotropic remeshing iterations (0: none)"""
    support_plane: bool = True
    """when every camera looks from above, cut the hull at the plane of the object's lowest rim points (a
    low quantile over the views), so the underside no camera sees does not stay a cone
    (dpi.preprocess.hull.support_plane)"""
    ground: bool = True
    """when every camera looks from above, remove from the masks the pixels that see the ground (photo-
    consistent under the ground plane's homography; needs the photos; dpi.preprocess.ground) before carving"""
    stereo: bool = True
    """carve what multi-view stereo sees as empty inside the hull (needs the photos; dpi.preprocess.stereo)"""


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
    ms.meshing_remove_connected_component_by_diameter(mincomponentdiag=pymeshlab.PercentageValue(MIN_COMPONENT))
    ms.meshing_repair_non_manifold_edges()
    ms.meshing_repair_non_manifold_vertices()
    ms.meshing_close_holes(maxholesize=100)
    if SMOOTHING_STEPS:
        ms.apply_coord_taubin_smoothing(stepsmoothnum=SMOOTHING_STEPS)
    if ms.current_mesh().face_number() > cfg.target_faces:
        ms.meshing_decimation_quadric_edge_collapse(targetfacenum=cfg.target_faces, preservenormal=True,
                                                    preservetopology=True, optimalplacement=True)
    if cfg.remesh_iterations:
        if REMESH_EDGE is None:
            area = ms.get_geometric_measures()["surface_area"]
            target = pymeshlab.PureValue(float(np.sqrt(4 * area / (np.sqrt(3) * cfg.target_faces))))
        else:
            target = pymeshlab.PercentageValue(REMESH_EDGE)
        ms.meshing_isotropic_explicit_remeshing(iterations=cfg.remesh_iterations, targetlen=target)
    ms.meshing_repair_non_manifold_edges()
    ms.meshing_remove_unreferenced_vertices()
    mesh = ms.current_mesh()
    vertices, faces = mesh.vertex_matrix().copy(), mesh.face_matrix().astype(np.int64).copy()
    if signed_volume(vertices, faces) < 0:
        faces = faces[:, ::-1].copy()
    return vertices, faces


def carve_hull(cameras: list[Camera], masks: list[np.ndarray],
               cfg: GeometryConfig) -> tuple[np.ndarray, np.ndarray, float, dict]:
    """The visual hull with the config's carving settings (dpi.preprocess.hull.visual_hull; its coarse search pass
    at most as fine as the fine one)."""
    return visual_hull(cameras, masks, cfg.resolution, min(COARSE_RESOLUTION, cfg.resolution), cfg.outside_votes,
                       in_frame=OBJECT_IN_FRAME)


def working_photos(cameras: list[Camera], masks: list[np.ndarray], images: list[np.ndarray],
                   max_size: int | None) -> tuple[list[Camera], list[np.ndarray], list[np.ndarray]]:
    """(cameras, masks, images) of the views with the longer side at most `max_size` px (area-
    downsampled; None or smaller views: as they are)."""
    import torch

    from dpi.io.images import resize, resize_mask, working_size

    out = ([], [], [])
    for camera, mask, image in zip(cameras, masks, images):
        width, height = working_size((camera.width, camera.height), max_size)
        if (width, height) != (camera.width, camera.height):
            camera, mask = camera.resized(width, height), resize_mask(mask, width, height)
            image = resize(torch.from_numpy(np.ascontiguousarray(image, np.float32)), height, width).numpy()
        for part, value in zip(out, (camera, mask, image)):
            part.append(value)
    return out


def without_ground(masks: list[np.ndarray], photos: tuple[list[Camera], list[np.ndarray], list[np.ndarray]],
                   up: np.ndarray, hull: tuple[np.ndarray, np.ndarray], stereo: StereoParams
                   ) -> tuple[list[np.ndarray], tuple[list[Camera], list[np.ndarray], list[np.ndarray]], dict]:
    """The full-size masks and the `working_photos` without the pixels that see the ground, found at the
    working photos' size (dpi.preprocess.ground.remove_ground), and the ground test's summary."""
    from dpi.io.images import resize_mask
    from dpi.preprocess.ground import remove_ground

    cameras, small, images = photos
    kept, summary = remove_ground(cameras, small, images, up, hull, stereo)
    masks = [m & ~resize_mask(before & ~after, m.shape[1], m.shape[0]) for m, before, after in zip(masks, small, kept)]
    return masks, (cameras, kept, images), summary


def reconstruct_surface(cameras: list[Camera], masks: list[np.ndarray], cfg: GeometryConfig | None = None,
                        images: list[np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray, dict]:
    """Watertight mesh (vertices, faces) of the object seen in the masks, and a summary with timings;
    with the views' linear RGB `images`, the masks lose the ground they took (`cfg.ground`) and the hull
    is carved further by multi-view stereo (`cfg.stereo`)."""
    cfg = cfg or GeometryConfig()
    times = {}
    start = time.perf_counter()
    field, origin, size, box = carve_hull(cameras, masks, cfg)
    up = seen_from_above(cameras, field, origin, size)
    photos = working_photos(cameras, masks, images, PHOTO_SIZE) if images is not None else None
    if cfg.ground and photos is not None and up is not None:
        from dpi.preprocess.stereo import StereoParams

        ground_start = time.perf_counter()
        masks, photos, ground = without_ground(masks, photos, up, marching_cubes(field, origin, size),
                                               StereoParams())
        times["ground_s"] = time.perf_counter() - ground_start
        if ground["removed_fraction"]:
            field, origin, size, box = carve_hull(cameras, masks, cfg)
        box["ground"] = ground
    plane = support_plane(cameras, masks, field, origin, size) if cfg.support_plane else None
    if plane is not None:
        field = cut_below(field, origin, size, *plane)
        box["support_plane"] = {"up": plane[0].tolist(), "height": plane[1]}
    times["carve_s"] = time.perf_counter() - start - times.get("ground_s", 0.0)
    if cfg.stereo and photos is not None:
        field, box["stereo"] = stereo_carve(field, origin, size, *photos, cfg)
        times["stereo_s"] = box["stereo"].pop("seconds")
    start = time.perf_counter()
    vertices, faces = marching_cubes(field, origin, size)
    times["marching_cubes_s"] = time.perf_counter() - start
    start = time.perf_counter()
    vertices, faces = clean_mesh(vertices, faces, cfg)
    times["cleanup_s"] = time.perf_counter() - start
    summary = {**box, "voxel_size": size, "grid": list(field.shape), "vertices": len(vertices), "faces": len(faces),
               **{k: round(v, 3) for k, v in times.items()}}
    return vertices, faces, summary


def stereo_carve(field: np.ndarray, origin: np.ndarray, size: float, cameras: list[Camera], masks: list[np.ndarray],
                 images: list[np.ndarray], cfg: GeometryConfig) -> tuple[np.ndarray, dict]:
    """The carved field with stereo's empty space removed, and a summary (depth coverage, voxels removed)."""
    from dpi.preprocess.stereo import StereoParams, carve_with_depths, depth_maps

    stereo = StereoParams()
    start = time.perf_counter()
    carved, inside, passes = field, int((field < 0).sum()), 0
    while passes < stereo.passes:
        depths = depth_maps(cameras, images, masks, *marching_cubes(carved, origin, size), stereo)
        before, carved, passes = carved, carve_with_depths(carved, origin, size, cameras, depths, stereo), passes + 1
        if ((before < 0) & (carved >= 0)).sum() < NEXT_PASS_FROM * inside:
            break
    coverage = float(np.mean([(d > 0).sum() / max(int(m.sum()), 1) for d, m in zip(depths, masks)]))
    removed = int(((field < 0) & (carved >= 0)).sum())
    return carved, {"depth_coverage": round(coverage, 4), "voxels_removed": removed,
                    "voxels_removed_fraction": round(removed / max(inside, 1), 4), "passes": passes,
                    "seconds": time.perf_counter() - start}


def read_mesh(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) of a PLY/OBJ mesh (trimesh, vertices not merged)."""
    import trimesh

    mesh = trimesh.load(path, force="mesh", process=False)
    return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)
