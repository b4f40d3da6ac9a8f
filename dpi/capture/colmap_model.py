"""A COLMAP model a capture brings (sparse/0/ or sparse/: cameras, images and points3D, as .txt or .bin): found
and checked against the images here; the poses stage reads it instead of running structure from motion."""

from __future__ import annotations

from pathlib import Path

from dpi.capture.model import CaptureError, inside_capture

MODEL_FOLDERS = ("sparse/0", "sparse")
"""where a capture's COLMAP model may lie, first found wins"""
MODEL_FILES = ("cameras", "images", "points3D")


def colmap_model_dir(root: Path) -> Path | None:
    """The capture's COLMAP model folder (one holding cameras.txt or cameras.bin), or None."""
    for folder in MODEL_FOLDERS:
        path = root / folder
        if any((path / f"cameras{suffix}").is_file() for suffix in (".txt", ".bin")):
            return path
    return None


def check_colmap_model(root: Path, folder: Path, names: list[str]) -> None:
    """The model is complete (each of its files in one format), reads, and registers images of the capture: else
    one CaptureError naming the folder and what is wrong."""
    import pycolmap

    inside_capture(root, folder, "the COLMAP model")
    for suffix in (".txt", ".bin"):
        present = [name for name in MODEL_FILES if (folder / f"{name}{suffix}").is_file()]
        if present and len(present) < len(MODEL_FILES):
            absent = ", ".join(f"{n}{suffix}" for n in MODEL_FILES if n not in present)
            raise CaptureError(f"{folder}: COLMAP model without {absent}")
        for name in present:
            inside_capture(root, folder / f"{name}{suffix}", "a COLMAP model file")
    try:
        model = pycolmap.Reconstruction(str(folder))
    except (RuntimeError, ValueError):
        raise CaptureError(f"{folder}: not a readable COLMAP model (cameras, images and points3D as .txt or "
                           ".bin)") from None
    registered = {Path(image.name).stem for image in model.images.values() if image.has_pose}
    known = registered & set(names)
    if not known:
        raise CaptureError(f"{folder}: the COLMAP model registers none of the images in images/ "
                           f"({len(registered)} images of other names)")
