"""Cameras of a Bundler file (`bundle.out`, v0.3), as Bundler, VisualSFM and many course datasets write them.

Per camera: a line `f k1 k2`, three lines of the world-to-camera rotation R and one of the translation t; the camera
looks down its -z axis with y up (OpenGL's axes, so the camera-to-world matrix is [R^T | -R^T t]), the principal
point at the image centre. The file names no images: its cameras follow the image list it was solved from (here
the photos' sorted names). A camera Bundler could not place has f = 0 and is left out. The keypoints stored with
the points are relative to the image centre: their extent says whether the cameras were solved on the stored
(`stored`) or the upright (`upright`) orientation of photos that carry an EXIF rotation (`solved_size`). The points
and their observations give the solution's own reprojection error under its lens (`BundlerSolution`).

A capture may bring one (`bundle.out` or `bundle/bundle.out`) instead of cameras: its validation checks it
(`check_bundler`) and the poses stage reads it, as it reads a COLMAP model. Its cameras follow the image list the
file was solved from: `list.txt` beside it or in the capture's root where there is one (each line's first word a
photo's path), else the photos' sorted names.
"""

from __future__ import annotations

import os
from pathlib import Path
from dataclasses import dataclass

import numpy as np

from dpi.capture.cameras import Camera
from dpi.capture.model import CaptureError, inside_capture


class BundlerError(ValueError):
    """A Bundler file that does not read, naming the file and the line."""


@dataclass(frozen=True)
class BundlerSolution:
    """A Bundler file's contents: per camera (f, k1, k2, R (3, 3), t (3,)), the points (N, 3), and each observation's
    camera and point index (M,) and keypoint (M, 2), relative to the image centre with y up."""

    cameras: list[tuple[float, float, float, np.ndarray, np.ndarray]]
    points: np.ndarray
    camera_index: np.ndarray
    point_index: np.ndarray
    keypoints: np.ndarray

    def reprojection_errors(self) -> np.ndarray:
        """(M,) pixels between each observation and its point projected by its camera under the file's own model
        (x = -f r(p) p with p = (R X + t)_xy / (R X + t)_z and r = 1 + k1 |p|^2 + k2 |p|^4)."""
        f, k1, k2 = (np.array([c[k] for c in self.cameras])[self.camera_index] for k in range(3))
        rotation = np.stack([c[3] for c in self.cameras])[self.camera_index]
        translation = np.stack([c[4] for c in self.cameras])[self.camera_index]
        local = np.einsum("mij,mj->mi", rotation, self.points[self.point_index]) + translation
        p = -local[:, :2] / local[:, 2:]
        r2 = (p * p).sum(1)
        projected = (f * (1 + k1 * r2 + k2 * r2 * r2))[:, None] * p
        return np.linalg.norm(projected - self.keypoints, axis=1)


def read_bundler(path: str | os.PathLike) -> BundlerSolution:
    """The cameras, points and observations of a Bundler v0.3 file; one that does not read, or whose counts do not
    match its lines, is a BundlerError naming the file and what is wrong."""
    with open(path, errors="replace") as f:
        lines = [line.split() for line in f if line.strip() and not line.startswith("#")]
    try:
        cameras_count, points_count = (int(v) for v in lines[0])
    except (IndexError, ValueError):
        raise BundlerError(f"{path}: not a Bundler v0.3 file (its first line is not the two counts of cameras and "
                           "points)") from None
    if cameras_count <= 0 or points_count < 0 or len(lines) < 1 + 5 * cameras_count + 3 * points_count:
        raise BundlerError(f"{path}: declares {cameras_count} cameras and {points_count} points but holds "
                           f"{len(lines) - 1} lines after the counts (5 a camera, 3 a point)")
    try:
        cameras = []
        for c in range(cameras_count):
            block = np.array(lines[1 + 5 * c: 6 + 5 * c], dtype=np.float64)
            if block.shape != (5, 3):
                raise ValueError(f"camera {c}'s lines do not hold 3 numbers each")
            cameras.append((float(block[0, 0]), float(block[0, 1]), float(block[0, 2]), block[1:4], block[4]))
        points, observations = [], []
        row = 1 + 5 * cameras_count
        for index in range(points_count):
            points.append([float(v) for v in lines[row]])
            views = lines[row + 2]
            observations.extend((int(views[4 * k + 1]), index, float(views[4 * k + 3]), float(views[4 * k + 4]))
                                for k in range(int(views[0])))
            row += 3
    except (IndexError, ValueError) as exc:
        raise BundlerError(f"{path}: not a Bundler v0.3 file ({str(exc)[:80]})") from None
    seen = np.array(observations, dtype=np.float64).reshape(-1, 4)
    return BundlerSolution(cameras, np.array(points, dtype=np.float64).reshape(-1, 3), seen[:, 0].astype(int),
                           seen[:, 1].astype(int), seen[:, 2:])


def solved_size(keypoints: np.ndarray, size: tuple[int, int]) -> tuple[int, int]:
    """(width, height) the cameras were solved at: the stored photo size `size` or its transpose, whichever holds
    the keypoints (relative to the centre); `size` when there are none."""
    width, height = size
    if len(keypoints) == 0:
        return width, height
    extent = np.abs(keypoints).max(axis=0)
    fits = extent[0] <= width / 2 + 1 and extent[1] <= height / 2 + 1
    return (width, height) if fits else (height, width)


ROLLS = {1: (0, 1), 3: (0, -1), 6: (1, -1), 8: (1, 1)}
"""EXIF orientation -> (axes swapped, sign) of the camera roll that turns a stored photo's camera into the upright
photo's (dpi.io.images.upright): 8 turns the image a quarter counter-clockwise (new right = old down, new up = old
right), 6 clockwise, 3 half a turn; the mirrored orientations are no camera's roll"""


def upright_camera(camera: Camera, orientation: int) -> Camera:
    """The camera of the photo turned upright by its EXIF `orientation` (the same centre, rolled about its axis)."""
    if orientation not in ROLLS:
        raise BundlerError(f"EXIF orientation {orientation} mirrors the photo: no camera takes it")
    swapped, sign = ROLLS[orientation]
    x, y = camera.c2w[:3, 0], camera.c2w[:3, 1]
    c2w = camera.c2w.copy()
    c2w[:3, 0], c2w[:3, 1] = ((sign * -y, sign * x) if swapped else (sign * x, sign * y))
    width, height = (camera.height, camera.width) if swapped else (camera.width, camera.height)
    return Camera(c2w, width, height, camera.fy if swapped else camera.fx, camera.fx if swapped else camera.fy,
                  width / 2, height / 2, camera.name)


def bundler_cameras(path: str | os.PathLike, names: list[str], size: tuple[int, int],
                    orientation: int = 1) -> dict[str, Camera]:
    """name -> Camera of a Bundler file whose cameras follow `names`, for photos of upright `size` (width, height, as
    dpi reads them) with EXIF `orientation`, turned upright; cameras with f = 0 (not placed) are left out."""
    solution = read_bundler(path)
    if len(solution.cameras) != len(names):
        raise BundlerError(f"{path}: {len(solution.cameras)} cameras for {len(names)} images")
    problem = cameras_problem(solution, names)
    if problem:
        raise BundlerError(f"{path}: {problem}")
    stored = tuple(size[::-1]) if orientation >= 5 else tuple(size)
    width, height = solved_size(solution.keypoints, stored)
    turn = orientation if (width, height) == stored else 1  # solved on the photos already upright
    out = {}
    for name, (focal, _, _, rotation, translation) in zip(names, solution.cameras):
        if focal <= 0:
            continue
        c2w = np.eye(4)
        c2w[:3, :3] = rotation.T
        c2w[:3, 3] = -rotation.T @ translation
        out[name] = upright_camera(Camera(c2w, width, height, focal, focal, width / 2, height / 2, name), turn)
    return out


ROTATION_TOLERANCE = 1e-3
"""largest entry of R^T R - I a Bundler rotation may have (the file's printed digits)"""


def cameras_problem(solution: BundlerSolution, names: list[str]) -> str | None:
    """Why the file's cameras (one per name, in order) cannot be used, naming the first bad camera (None: they can):
    not finite, a negative focal, a rotation that is not one, or no camera placed at all (every focal 0)."""
    for c, (name, (focal, k1, k2, rotation, translation)) in enumerate(zip(names, solution.cameras)):
        where = f"camera {c} (image {name!r})"
        if not np.isfinite([focal, k1, k2, *rotation.ravel(), *translation]).all():
            return f"{where}: its focal, distortion, rotation or translation is not finite (NaN or infinite)"
        if focal < 0:
            return f"{where}: focal length {focal:g} px; it must be positive (0: a camera Bundler did not place)"
        if focal > 0 and np.abs(rotation.T @ rotation - np.eye(3)).max() > ROTATION_TOLERANCE:
            return f"{where}: its rotation is not orthonormal"
    if not any(c[0] > 0 for c in solution.cameras):
        return "every camera's focal length is 0: Bundler placed none of them"
    return None


BUNDLE_FILES = ("bundle.out", "bundle/bundle.out")
"""where a capture's Bundler file may lie, the first found wins"""
LIST_FILE = "list.txt"


def bundler_file(root: Path) -> Path | None:
    """The capture's Bundler file, or None."""
    return next((root / name for name in BUNDLE_FILES if (root / name).is_file()), None)


def list_file(bundle: Path, root: Path) -> Path | None:
    """The image list the Bundler file was solved from: `list.txt` beside it, else in the capture's root; None."""
    return next((folder / LIST_FILE for folder in (bundle.parent, root) if (folder / LIST_FILE).is_file()), None)


def bundler_names(bundle: Path, root: Path, names: list[str]) -> list[str]:
    """The image each of the file's cameras belongs to: `list_file` in its order, each line's first word a photo's
    path matched to `names` by its stem; else `names` sorted. A line naming no photo of the capture is a BundlerError
    naming it."""
    listed = list_file(bundle, root)
    if listed is None:
        return sorted(names)
    known = set(names)
    order = []
    for number, line in enumerate(listed.read_text(errors="replace").splitlines(), 1):
        words = line.split()
        if not words:
            continue
        stem = Path(words[0]).stem
        if stem not in known:
            raise BundlerError(f"{listed}: line {number} names {words[0][:80]!r}, which is not a photo of the "
                               "capture's images/")
        order.append(stem)
    return order


def capture_bundler_cameras(root: Path, bundle: Path, images: dict[str, Path], size: tuple[int, int]
                            ) -> dict[str, Camera]:
    """name -> Camera of the capture's Bundler file for its photos `images` (name -> file) of upright `size`: the
    cameras in list.txt's order (`bundler_names`), turned by the photos' EXIF orientation (BundlerError where they
    cannot be used)."""
    from dpi.io.images import exif_orientation

    orientation = exif_orientation(next(iter(images.values())))  # 1 for an EXR
    return bundler_cameras(bundle, bundler_names(bundle, root, list(images)), size, orientation)


def check_bundler(root: Path, bundle: Path, images: dict[str, Path], size: tuple[int, int]) -> None:
    """The capture's Bundler file reads and its cameras can be used (`capture_bundler_cameras`), inside the capture:
    else one CaptureError naming the file and the camera."""
    inside_capture(root, bundle, "the Bundler file")
    listed = list_file(bundle, root)
    if listed is not None:
        inside_capture(root, listed, "the Bundler image list")
    try:
        capture_bundler_cameras(root, bundle, images, size)
    except BundlerError as exc:
        raise CaptureError(str(exc)) from None
