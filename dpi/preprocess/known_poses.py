"""Sparse points of a capture whose cameras are given: COLMAP's features and matches, triangulated with the given
poses and intrinsics held fixed.

A capture that brings its cameras but no masks needs the points as much as a photos-only one: the masks' parallax
seeds and the support plane (dpi.preprocess.depth_seeds) and the points witness (dpi.preprocess.mask_confidence)
come from them. The database's images, cameras and matches are COLMAP's own (one camera per image); the
reconstruction holds the given cameras under the database's ids, and COLMAP's point triangulator fills it.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from dpi.capture.cameras import Camera
from dpi.preprocess.sfm import (CV_TO_GL, EXHAUSTIVE_MAX_IMAGES, SfMConfig, SparseModel, extraction_options,
                                fresh_work, match_features, sparse_points)

log = logging.getLogger(__name__)


def camera_from_world(camera: Camera) -> np.ndarray:
    """COLMAP's 3x4 world-to-camera matrix (OpenCV axes) of a dpi camera (OpenGL camera-to-world): the inverse of
    dpi.preprocess.sfm.colmap_to_camera."""
    return (CV_TO_GL @ np.linalg.inv(camera.c2w))[:3]


def colmap_camera(camera: Camera, camera_id: int):
    """The pycolmap camera of a dpi camera: a pinhole, or OpenCV's model (fisheye or not) where it has a lens."""
    import pycolmap

    lens, intrinsics = camera.lens, [camera.fx, camera.fy, camera.cx, camera.cy]
    if lens is None:
        model, params = "PINHOLE", intrinsics
    elif lens.fisheye:
        model, params = "OPENCV_FISHEYE", intrinsics + [lens.k1, lens.k2, lens.k3, lens.k4]
    else:
        model, params = "OPENCV", intrinsics + [lens.k1, lens.k2, lens.p1, lens.p2]
    return pycolmap.Camera(model=model, width=camera.width, height=camera.height, params=params, camera_id=camera_id)


def triangulate_known(images: list[Path], cameras: dict[str, Camera], work_dir: str | Path,
                      cfg: SfMConfig | None = None, threads: int = 1) -> SparseModel:
    """The sparse points of `images` (all in one folder; view name = file stem) under their given `cameras`, in
    `work_dir` (database, model). The cameras come back as given; a capture without matches gets no points."""
    import pycolmap

    cfg = cfg or SfMConfig()
    images = [p for p in map(Path, images) if p.stem in cameras]
    images, image_dir, work = fresh_work(images, work_dir)
    database = work / "database.db"
    pycolmap.extract_features(database, image_dir, image_names=[p.name for p in images],
                              camera_mode=pycolmap.CameraMode.PER_IMAGE,
                              extraction_options=extraction_options(cfg, threads), device=pycolmap.Device.cpu)
    match_features(database, "exhaustive" if len(images) <= EXHAUSTIVE_MAX_IMAGES else "sequential", threads)
    model = pycolmap.Reconstruction()
    with pycolmap.Database.open(database) as db:
        for image in db.read_all_images():
            camera = cameras[Path(image.name).stem]
            given = colmap_camera(camera, image.camera_id)
            db.update_camera(given)  # the triangulator checks the database's camera against the reconstruction's
            model.add_camera_with_trivial_rig(given)
            model.add_image_with_trivial_frame(
                pycolmap.Image(name=image.name, camera_id=image.camera_id, image_id=image.image_id),
                pycolmap.Rigid3d(camera_from_world(camera)))
    options = pycolmap.IncrementalPipelineOptions()
    options.num_threads = threads
    model = pycolmap.triangulate_points(model, database, image_dir, work / "sparse", options=options)
    xyz, rgb, on_object = sparse_points(model, cameras)
    summary = {"cameras": "given", "images": len(images), "registered": len(images), "points": len(xyz),
               "object_points": int(on_object.sum()),
               "mean_reprojection_error_px": float(model.compute_mean_reprojection_error())}
    log.info("points triangulated under the given cameras: %s", summary)
    return SparseModel(dict(cameras), xyz, rgb, on_object, summary)
