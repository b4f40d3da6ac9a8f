"""A COLMAP model a capture brings (sparse/0/ or sparse/: cameras, images and points3D, as .txt or .bin): found
and checked against the images here; the poses stage reads it instead of running structure from motion."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dpi.capture.model import CaptureError, inside_capture

MODEL_FOLDERS = ("sparse/0", "sparse")
"""where a capture's COLMAP model may lie, first found wins"""
MODEL_FILES = ("cameras", "images", "points3D")
READ_MODELS = ("SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL", "RADIAL", "OPENCV", "OPENCV_FISHEYE")
"""the COLMAP camera models dpi reads (dpi.preprocess.sfm turns each into intrinsics and a lens)"""


def colmap_model_dir(root: Path) -> Path | None:
    """The capture's COLMAP model folder (one holding cameras.txt or cameras.bin), or None."""
    for folder in MODEL_FOLDERS:
        path = root / folder
        if any((path / f"cameras{suffix}").is_file() for suffix in (".txt", ".bin")):
            return path
    return None


def check_colmap_model(root: Path, folder: Path, names: list[str], size: tuple[int, int]) -> None:
    """The model is complete (each of its files in one format), reads, registers images of the capture, and the
    cameras and poses of those are usable (a model dpi reads, finite intrinsics with a positive focal length and
    principal point inside the image, the images' `size` (width, height), finite poses): else one CaptureError naming
    the folder and what is wrong."""
    import pycolmap

    inside_capture(root, folder, "the COLMAP model")
    for suffix in (".txt", ".bin"):
        present = [name for name in MODEL_FILES if (folder / f"{name}{suffix}").is_file()]
        if present and len(present) < len(MODEL_FILES):
            absent = ", ".join(f"{n}{suffix}" for n in MODEL_FILES if n not in present)
            raise CaptureError(f"{folder}: COLMAP model without {absent}")
        for name in present:
            inside_capture(root, folder / f"{name}{suffix}", "a COLMAP model file")
    problem = text_model_problem(folder) or binary_model_problem(folder)
    if problem:
        raise CaptureError(f"{folder}: {problem}")
    try:
        model = pycolmap.Reconstruction(str(folder))
    except Exception as exc:  # pycolmap's readers raise RuntimeError, ValueError, IndexError, ... on bad files
        raise CaptureError(f"{folder}: not a readable COLMAP model (cameras, images and points3D as .txt or "
                           f".bin; pycolmap: {type(exc).__name__})") from None
    registered = {Path(image.name).stem: image for image in model.images.values() if image.has_pose}
    known = [image for stem, image in registered.items() if stem in set(names)]
    if not known:
        raise CaptureError(f"{folder}: the COLMAP model registers none of the images in images/ "
                           f"({len(registered)} images of other names)")
    for image in known:
        camera = model.cameras[image.camera_id]
        check_colmap_camera(folder, camera, image.name)
        if (camera.width, camera.height) != tuple(size):
            raise CaptureError(f"{folder}: camera {camera.camera_id} (of image {image.name!r}) is {camera.width} x "
                               f"{camera.height} px but the images are {size[0]} x {size[1]}: the model was made from "
                               "other copies of the photos (resized or rotated)")
        pose = np.asarray(image.cam_from_world().matrix(), dtype=np.float64)
        if not np.isfinite(pose).all():
            raise CaptureError(f"{folder}: image {image.name!r}: its pose is not finite (NaN or infinite)")


def text_model_problem(folder: Path) -> str | None:
    """A text model's camera or image whose numbers are not finite, named before pycolmap reads it (its reader
    names no line): cameras.txt's parameters (CAMERA_ID MODEL WIDTH HEIGHT PARAMS...), images.txt's poses (every
    other line: IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME). None when both are finite or the model is binary."""
    def numbers(words: list[str]) -> np.ndarray:
        try:
            return np.array([float(w) for w in words])
        except ValueError:
            return np.array([np.nan])

    cameras, images = folder / "cameras.txt", folder / "images.txt"
    if cameras.is_file():
        for line in cameras.read_text(errors="replace").splitlines():
            words = line.split()
            if words and not line.startswith("#") and not np.isfinite(numbers(words[2:])).all():
                return f"camera {words[0]}: its parameters are not finite (NaN or infinite) in cameras.txt"
    if images.is_file():
        rows = [line.split() for line in images.read_text(errors="replace").splitlines() if not line.startswith("#")]
        for words in rows[::2]:
            if len(words) >= 10 and not np.isfinite(numbers(words[1:8])).all():
                return f"image {' '.join(words[9:])!r}: its pose is not finite (NaN or infinite) in images.txt"
    return None


CAMERA_PARAMS = {0: 3, 1: 4, 2: 4, 3: 5, 4: 8, 5: 8, 6: 12, 7: 5, 8: 4, 9: 5, 10: 12, 11: 16}
"""parameters of each COLMAP camera model id (SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, ...) in cameras.bin"""


def binary_model_problem(folder: Path) -> str | None:
    """A binary model's camera or image whose numbers are not finite, named before pycolmap reads it (its reader turns
    a NaN quaternion into another rotation without a word): cameras.bin's parameters, images.bin's poses. None when
    both are finite, the model is text, or a file does not parse (pycolmap's reader then says so)."""
    import struct

    cameras, images = folder / "cameras.bin", folder / "images.bin"
    try:
        if cameras.is_file():
            data, at = cameras.read_bytes(), 8
            for _ in range(struct.unpack_from("<Q", data, 0)[0]):
                camera_id, model = struct.unpack_from("<Ii", data, at)
                count = CAMERA_PARAMS[model]
                params = struct.unpack_from(f"<{count}d", data, at + 24)
                if not np.isfinite(params).all():
                    return f"camera {camera_id}: its parameters are not finite (NaN or infinite) in cameras.bin"
                at += 24 + 8 * count
        if images.is_file():
            data, at = images.read_bytes(), 8
            for _ in range(struct.unpack_from("<Q", data, 0)[0]):
                pose = struct.unpack_from("<7d", data, at + 4)
                end = data.index(b"\0", at + 64)
                name = data[at + 64:end].decode(errors="replace")
                if not np.isfinite(pose).all():
                    return f"image {name!r}: its pose is not finite (NaN or infinite) in images.bin"
                at = end + 1 + 8 + 24 * struct.unpack_from("<Q", data, end + 1)[0]
    except (struct.error, KeyError, ValueError):
        return None
    return None


def check_colmap_camera(folder: Path, camera, image: str) -> None:
    """One CaptureError naming the model folder, the image and the cause, unless the camera is usable."""
    where = f"{folder}: camera {camera.camera_id} (of image {image!r})"
    if camera.model_name not in READ_MODELS:
        raise CaptureError(f"{where}: COLMAP camera model {camera.model_name} is not read by dpi (use "
                           f"{', '.join(READ_MODELS)})")
    params = np.asarray(camera.params, dtype=np.float64)
    if not np.isfinite(params).all():
        raise CaptureError(f"{where}: its parameters are not finite (NaN or infinite)")
    focal = [params[i] for i in camera.focal_length_idxs()]
    if min(focal) <= 0:
        raise CaptureError(f"{where}: focal length {min(focal):g} px; it must be positive")
    if camera.width <= 0 or camera.height <= 0:
        raise CaptureError(f"{where}: image size {camera.width} x {camera.height}; it must be positive")
    cx, cy = (params[i] for i in camera.principal_point_idxs())
    if not (0 < cx < camera.width and 0 < cy < camera.height):
        raise CaptureError(f"{where}: principal point ({cx:g}, {cy:g}) px lies outside its {camera.width} x "
                           f"{camera.height} image")
