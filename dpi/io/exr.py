"""OpenEXR reading and writing: linear HDR images as float32 numpy arrays (H, W, C).

All EXR access of dpi goes through this module. Reading places the data window inside the
display window, accepts half or float channels, by name: RGB(A) or Y (grey).
Writing is atomic and refuses NaN/Inf.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import OpenEXR

RGB_NAMES = ("R", "G", "B")


class EXRError(ValueError):
    """An EXR file could not be read or written; the message names the file."""


def _channel_stack(path: Path, channels: dict[str, np.ndarray]) -> np.ndarray:
    """Stack the colour channels of one EXR part into (H, W, C), by name: R, G, B (C = 3) or Y (grey, C = 1);
    alpha and other channels are ignored, and a file with neither (a lone depth channel Z) is an error."""
    if all(n in channels for n in RGB_NAMES):
        return np.stack([channels[n] for n in RGB_NAMES], axis=-1)
    if "Y" in channels:
        return channels["Y"][..., None]
    raise EXRError(f"{path}: EXR channels {', '.join(sorted(channels))} hold no image: dpi reads R, G, B "
                   "(with or without A) or Y (grey)")


def read_exr(path: str | os.PathLike) -> np.ndarray:
    """Read an EXR as float32 (H, W, C) with C = 3 (RGB) or 1; pixels outside the data window are 0."""
    path = Path(path)
    if not path.is_file():
        raise EXRError(f"{path}: file does not exist")
    try:
        with OpenEXR.File(str(path), separate_channels=True) as exr:
            header = exr.header()
            data_window = [tuple(int(v) for v in w) for w in header["dataWindow"]]
            display_window = [tuple(int(v) for v in w) for w in header["displayWindow"]]
            channels = {name: np.array(c.pixels) for name, c in exr.channels().items()}
    except (RuntimeError, ValueError, OSError) as exc:  # a truncated file raises ValueError("... has 0 parts")
        raise EXRError(f"{path}: not a readable EXR file ({exc})") from exc
    data = _channel_stack(path, channels).astype(np.float32)
    (dx0, dy0), (dx1, dy1) = data_window
    (wx0, wy0), (wx1, wy1) = display_window
    if (dx0, dy0, dx1, dy1) == (wx0, wy0, wx1, wy1):
        return data
    image = np.zeros((wy1 - wy0 + 1, wx1 - wx0 + 1, data.shape[-1]), np.float32)
    ys, xs = slice(max(dy0, wy0), min(dy1, wy1) + 1), slice(max(dx0, wx0), min(dx1, wx1) + 1)
    image[ys.start - wy0 : ys.stop - wy0, xs.start - wx0 : xs.stop - wx0] = data[
        ys.start - dy0 : ys.stop - dy0, xs.start - dx0 : xs.stop - dx0
    ]
    return image


def write_exr(path: str | os.PathLike, image: np.ndarray, half: bool = False) -> None:
    """Write (H, W), (H, W, 1) or (H, W, 3) linear data as an EXR (float32 or half), atomically."""
    from dpi.io.atomic import atomic_path

    path = Path(path)
    image = np.asarray(image)
    if image.ndim == 2:
        image = image[..., None]
    if image.ndim != 3 or image.shape[-1] not in (1, 3):
        raise EXRError(f"{path}: can only write (H, W, 1|3) images, got shape {image.shape}")
    if not np.isfinite(image).all():
        raise EXRError(f"{path}: refusing to write an image with NaN/Inf values")
    dtype = np.float16 if half else np.float32
    names = RGB_NAMES if image.shape[-1] == 3 else ("Y",)
    channels = {n: np.ascontiguousarray(image[..., i].astype(dtype)) for i, n in enumerate(names)}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_path(path) as tmp:
        with OpenEXR.File(header, channels) as exr:
            exr.write(str(tmp))
