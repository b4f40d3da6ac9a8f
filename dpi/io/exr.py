"""OpenEXR reading and writing: linear HDR images as float32 numpy arrays (H, W, C).

All EXR access of dpi goes through this module. Reading checks the headers' windows against
the pixel bound (dpi.io.pixel_bound) before any pixel is read, places the data window inside the display window,
and accepts half or float channels by name, in the first part (of one or several) that holds an image: RGB(A),
CIE XYZ (converted to linear Rec. 709) or Y (grey).
Writing is atomic and refuses NaN/Inf.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import OpenEXR

from dpi.io.pixel_bound import size_problem

RGB_NAMES = ("R", "G", "B")
XYZ_NAMES = ("X", "Y", "Z")
XYZ_TO_RGB = np.array([[3.2404542, -1.5371385, -0.4985314],
                       [-0.9692660, 1.8760108, 0.0415560],
                       [0.0556434, -0.2040259, 1.0572252]], np.float32)
"""CIE XYZ to linear Rec. 709 RGB (D65), for an EXR that stores X, Y, Z channels"""


class EXRError(ValueError):
    """An EXR file could not be read or written; the message names the file."""


def image_kind(names: set[str]) -> str | None:
    """How one part's channels hold an image, by name: "rgb" (R, G, B, with or without A), "xyz" (CIE X, Y, Z),
    "grey" (Y alone) or "chroma" (Y with RY / BY, luminance-chroma); None: no image (a lone depth channel Z)."""
    if all(n in names for n in RGB_NAMES):
        return "rgb"
    if all(n in names for n in XYZ_NAMES):
        return "xyz"
    if "Y" in names:
        return "chroma" if {"RY", "BY"} & names else "grey"
    return None


WINDOWS = {"dataWindow": "data window", "displayWindow": "display window"}


def window(path: Path, header: dict, key: str) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1) of a header's data or display window (WINDOWS), its size within the pixel bound
    (dpi.io.pixel_bound)."""
    (x0, y0), (x1, y1) = ((int(v) for v in corner) for corner in header[key])
    problem = size_problem(x1 - x0 + 1, y1 - y0 + 1)
    if problem:
        raise EXRError(f"{path}: its {WINDOWS[key]} {problem}")
    return x0, y0, x1, y1


def image_part(path: Path) -> tuple[int, tuple[int, int, int, int], tuple[int, int, int, int], str]:
    """The first part of an EXR (single or multipart) whose channels hold an image: its index, data and display
    windows and kind (`image_kind`), from the headers alone; every part's windows are bounded before any pixel is
    read."""
    try:
        with OpenEXR.File(str(path), header_only=True) as exr:
            headers = [dict(part.header) for part in exr.parts]
    except (RuntimeError, ValueError, OSError) as exc:  # a truncated file raises ValueError("... has 0 parts")
        raise EXRError(f"{path}: not a readable EXR file ({exc})") from None
    found = None
    for index, header in enumerate(headers):
        data, display = window(path, header, "dataWindow"), window(path, header, "displayWindow")
        kind = image_kind({channel.name for channel in header.get("channels", [])})
        if found is None and kind is not None:
            found = index, data, display, kind
    if found is None:
        names = sorted({c.name for header in headers for c in header.get("channels", [])})
        raise EXRError(f"{path}: EXR channels {', '.join(names) or '(none)'} hold no image: dpi reads R, G, B "
                       "(with or without A) or Y (grey), or CIE X, Y, Z")
    if found[3] == "chroma":
        raise EXRError(f"{path}: a luminance-chroma EXR (Y, RY, BY channels): dpi reads RGB, XYZ or grey; save it "
                       "as RGB")
    (dx0, dy0, dx1, dy1), (wx0, wy0, wx1, wy1) = found[1], found[2]
    if dx1 < wx0 or dx0 > wx1 or dy1 < wy0 or dy0 > wy1:
        raise EXRError(f"{path}: its data window {found[1]} lies outside its display window {found[2]}: no pixel "
                       "of the image is stored")
    return found


def _channel_stack(channels: dict[str, np.ndarray], kind: str) -> np.ndarray:
    """One part's channels as (H, W, C) linear float32: RGB (C = 3; XYZ converted to it) or grey (C = 1)."""
    if kind == "grey":
        return channels["Y"][..., None].astype(np.float32)
    stack = np.stack([channels[n] for n in (RGB_NAMES if kind == "rgb" else XYZ_NAMES)], axis=-1).astype(np.float32)
    return stack if kind == "rgb" else stack @ XYZ_TO_RGB.T


def read_exr(path: str | os.PathLike) -> np.ndarray:
    """Read an EXR as float32 (H, W, C) with C = 3 (RGB) or 1 (grey), from its first part that holds an image
    (`image_part`); pixels of the display window outside the data window are 0."""
    path = Path(path)
    if not path.is_file():
        raise EXRError(f"{path}: file does not exist")
    index, (dx0, dy0, dx1, dy1), (wx0, wy0, wx1, wy1), kind = image_part(path)
    try:
        with OpenEXR.File(str(path), separate_channels=True) as exr:
            channels = {name: np.array(c.pixels) for name, c in exr.parts[index].channels.items()}
        data = _channel_stack(channels, kind)
    except (RuntimeError, ValueError, OSError, IndexError, KeyError) as exc:  # truncated: parts or channels missing
        raise EXRError(f"{path}: not a readable EXR file ({type(exc).__name__})") from None
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
