"""The working resolution of the inverse stages: a capture's images and masks area-downsampled once.

Photos are 1600-4000 px; init, methods and evaluation render every view at the size they fit, so
they work on copies whose longer side is `ProblemConfig.resolution` px (None: the capture's own).
The copies (linear EXR images and masks) and the cameras, scaled to them, live in the scene's
results folder (`SceneLayout.working_dir`), written once per size and source, atomically, and
reused by every later job; a changed source image is resampled again.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from dpi.capture import Capture
from dpi.capture.view_copies import cached_copies, source_stamp
from dpi.io.images import read_image, read_mask, resize, resize_mask, working_size

MANIFEST = "working.json"


def working_capture(capture: Capture, resolution: int | None, folder: str | Path) -> Capture:
    """The capture at the working resolution: itself when it is no larger, else views whose images and
    masks are area-downsampled copies in folder/{w}x{h}/ and whose cameras are scaled to them."""
    size = working_size(capture.image_size, resolution)
    if size == tuple(capture.image_size):
        return capture
    views = cached_copies(
        capture.views, Path(folder) / f"{size[0]}x{size[1]}", MANIFEST, source_stamp,
        image=lambda v: resize(torch.from_numpy(read_image(v.image)), size[1], size[0]).numpy(),
        mask=lambda v: resize_mask(read_mask(v.mask), *size).astype(np.float32),
        camera=lambda v: None if v.camera is None else v.camera.resized(*size))
    return replace(capture, views=views, image_size=size)
