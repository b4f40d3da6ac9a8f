"""Lens distortion removed once: each distorted view's image and mask resampled by OpenCV to the pinhole camera
with the same intrinsics, written beside capture.json, so every later stage (masks, geometry, init, the methods,
evaluation) works on pinhole views. A given lens is removed at capture time; one the poses stage fits, right
after it (`with_cameras`).

The copies are linear EXR (images) and EXR masks (dpi.capture.view_copies), reused while their source is
unchanged; pixels the pinhole sees beyond the photo's edge are black and outside the
mask."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from dpi.capture.cameras import Camera, Lens
from dpi.capture.model import Capture
from dpi.capture.view_copies import cached_copies, source_stamp
from dpi.io.images import read_image, read_mask

MANIFEST = "undistorted.json"


def intrinsics(camera: Camera) -> np.ndarray:
    """OpenCV's 3x3 camera matrix K of a camera (pixel origin at the top-left corner, y down)."""
    return np.array([[camera.fx, 0.0, camera.cx], [0.0, camera.fy, camera.cy], [0.0, 0.0, 1.0]])


def undistortion_maps(camera: Camera, lens: Lens) -> tuple[np.ndarray, np.ndarray]:
    """For every pixel of the pinhole image (same K), where it lies in the distorted photo: (x, y) maps."""
    k, size = intrinsics(camera), (camera.width, camera.height)
    if lens.fisheye:
        return cv2.fisheye.initUndistortRectifyMap(k, lens.coefficients(), np.eye(3), k, size, cv2.CV_32FC1)
    return cv2.initUndistortRectifyMap(k, lens.coefficients(), np.eye(3), k, size, cv2.CV_32FC1)


def undistort_image(image: np.ndarray, camera: Camera, lens: Lens, nearest: bool = False) -> np.ndarray:
    """A photo (H, W[, C]) taken through `lens` as the pinhole `camera` would have taken it (bilinear; nearest
    for masks); pixels that fall outside the photo are 0."""
    map_x, map_y = undistortion_maps(camera, lens)
    return cv2.remap(image, map_x, map_y, cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def distort_image(image: np.ndarray, camera: Camera, lens: Lens) -> np.ndarray:
    """The inverse of `undistort_image`: a pinhole image (H, W[, C]) as the photo through `lens` shows it (for
    synthetic captures with a lens and for tests)."""
    k = intrinsics(camera)
    ys, xs = np.mgrid[0:camera.height, 0:camera.width].astype(np.float64)
    points = np.stack([xs.ravel(), ys.ravel()], -1)[:, None, :]
    if lens.fisheye:
        pinhole = cv2.fisheye.undistortPoints(points, k, lens.coefficients(), P=k)
    else:
        pinhole = cv2.undistortPoints(points, k, lens.coefficients(), R=None, P=k,
                                      criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-9))
    maps = pinhole.reshape(camera.height, camera.width, 2).astype(np.float32)
    return cv2.remap(image, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def undistorted_capture(capture: Capture, folder: str | Path) -> Capture:
    """The capture with every view whose camera has a lens replaced by undistorted copies of its image and mask
    in `folder` and its camera made a pinhole; itself when no camera has a lens."""
    if not any(v.camera is not None and v.camera.lens is not None for v in capture.views):
        return capture
    distorted = [v for v in capture.views if v.camera is not None and v.camera.lens is not None]
    copies = dict(zip((v.name for v in distorted), cached_copies(
        distorted, folder, MANIFEST, lambda v: [source_stamp(v), v.camera.lens.to_json()],
        image=lambda v: undistort_image(read_image(v.image), v.camera, v.camera.lens),
        mask=lambda v: undistort_image(read_mask(v.mask).astype(np.float32), v.camera, v.camera.lens, nearest=True),
        camera=lambda v: replace(v.camera, lens=None))))
    views = [copies.get(v.name, v) for v in capture.views]
    return replace(capture, views=views)


def with_cameras(capture: Capture, cameras: dict[str, Camera], folder: str | Path) -> Capture:
    """The capture with derived `cameras` (structure from motion's; views without one dropped) and, where they
    carry a fitted lens, its views undistorted into `folder` (the poses stage writes the copies first)."""
    return undistorted_capture(capture.with_derived(cameras=cameras), folder)
