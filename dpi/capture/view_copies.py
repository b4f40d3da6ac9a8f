"""Views whose image and mask are derived copies (linear EXR) kept in a folder: made once per source, reused by
every later job, made again when a source or what the copy depends on changes (a manifest of stamps)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from dpi.capture.cameras import Camera
from dpi.capture.model import View
from dpi.io.atomic import write_json
from dpi.io.exr import write_exr


def source_stamp(view: View) -> list:
    """What identifies a view's sources: paths, sizes and modification times of image and mask."""
    return [[str(p), p.stat().st_size, p.stat().st_mtime_ns] for p in (view.image, view.mask) if p is not None]


def cached_copies(views: list[View], folder: str | Path, manifest_name: str, stamp: Callable[[View], Any],
                  image: Callable[[View], np.ndarray], mask: Callable[[View], np.ndarray],
                  camera: Callable[[View], Camera | None]) -> list[View]:
    """`views` with their image and mask replaced by copies folder/images/{view}.exr and folder/masks/{view}.exr
    (`image(view)`, `mask(view)`, rewritten where `stamp(view)` differs from the manifest's or a copy is missing)
    and their camera by `camera(view)`."""
    folder = Path(folder)
    manifest_path = folder / manifest_name
    manifest = json.loads(manifest_path.read_text()) if manifest_path.is_file() else {}
    copies, changed = [], False
    for view in views:
        image_file, mask_file = folder / "images" / f"{view.name}.exr", folder / "masks" / f"{view.name}.exr"
        key = stamp(view)
        if manifest.get(view.name) != key or not image_file.is_file() or (view.mask and not mask_file.is_file()):
            write_exr(image_file, image(view))
            if view.mask is not None:
                write_exr(mask_file, mask(view))
            manifest[view.name], changed = key, True
        copies.append(View(view.name, image_file, mask_file if view.mask is not None else None, camera(view),
                           view.held_out))
    if changed:
        write_json(manifest_path, manifest)
    return copies
