"""The working resolution of the inverse stages: a capture's images and masks area-downsampled once.

Photos are 1600-4000 px; init, methods and evaluation render every view at the size they fit, so
they work on copies whose longer side is `ProblemConfig.resolution` px (None: the capture's own).
The copies (linear EXR images and masks) and the cameras, scaled to them, live in the scene's
results folder (`SceneLayout.working_dir`), written once per size and source, atomically, and
reused by every later job; a changed source image is resampled again.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from dpi.capture import Capture, View
from dpi.capture.model import source_stamp
from dpi.io.atomic import write_json
from dpi.io.exr import write_exr
from dpi.io.images import read_image, read_mask, resize, resize_mask, working_size

MANIFEST = "working.json"


def working_capture(capture: Capture, resolution: int | None, folder: str | Path) -> Capture:
    """The capture at the working resolution: itself when it is no larger, else views whose images and
    masks are area-downsampled copies in folder/{w}x{h}/ and whose cameras are scaled to them."""
    size = working_size(capture.image_size, resolution)
    if size == tuple(capture.image_size):
        return capture
    root = Path(folder) / f"{size[0]}x{size[1]}"
    manifest_path = root / MANIFEST
    manifest = json.loads(manifest_path.read_text()) if manifest_path.is_file() else {}
    views, changed = [], False
    for view in capture.views:
        image, mask = root / "images" / f"{view.name}.exr", root / "masks" / f"{view.name}.exr"
        stamp = source_stamp(view)
        if manifest.get(view.name) != stamp or not image.is_file() or (view.mask and not mask.is_file()):
            pixels = torch.from_numpy(read_image(view.image))
            write_exr(image, resize(pixels, size[1], size[0]).numpy())
            if view.mask is not None:
                write_exr(mask, resize_mask(read_mask(view.mask), *size).astype(np.float32))
            manifest[view.name], changed = stamp, True
        camera = None if view.camera is None else view.camera.resized(*size)
        views.append(View(view.name, image, mask if view.mask is not None else None, camera, view.held_out))
    if changed:
        write_json(manifest_path, manifest)
    return replace(capture, views=views, image_size=size)
