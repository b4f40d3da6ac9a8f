"""LDR/HDR image files as linear float32 arrays: sRGB PNG/JPG decoding (8 or 16 bits, grey or colour),
EXR, masks, PNG output."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import torch
from PIL import Image

from dpi.io.atomic import atomic_path
from dpi.io.exr import EXRError, read_exr
from dpi.io.pixel_bound import size_problem

LDR_SUFFIXES = (".png", ".jpg", ".jpeg")
HDR_SUFFIXES = (".exr",)
IMAGE_SUFFIXES = LDR_SUFFIXES + HDR_SUFFIXES


class ImageError(ValueError):
    """An image file is missing, unreadable or holds unusable values; the message names the file."""


REC709_LUMA = (0.2126, 0.7152, 0.0722)
REC601_LUMA = (0.299, 0.587, 0.114)
"""the grey of an RGB mask image (as PIL's "L" mode)"""


def luminance(rgb: np.ndarray | torch.Tensor) -> np.ndarray | torch.Tensor:
    """Rec. 709 luminance (...,) of linear RGB (..., 3), as numpy or torch (keeping dtype and device)."""
    if isinstance(rgb, torch.Tensor):
        return rgb @ torch.tensor(REC709_LUMA, dtype=rgb.dtype, device=rgb.device)
    rgb = np.asarray(rgb)
    return rgb @ np.array(REC709_LUMA, dtype=rgb.dtype if rgb.dtype.kind == "f" else np.float64)


def with_luminance(rgb: np.ndarray, level: np.ndarray | float) -> np.ndarray:
    """Colours (..., 3) rescaled to Rec. 709 luminance `level` (broadcast over leading axes): albedos from tints."""
    rgb = np.asarray(rgb, dtype=np.float64)
    return rgb * (np.asarray(level, dtype=np.float64) / luminance(rgb))[..., None]


def working_size(image_size: tuple[int, int], resolution: int | None) -> tuple[int, int]:
    """(width, height) with the longer side at most `resolution` px, the aspect kept (None: unchanged)."""
    width, height = image_size
    longer = max(width, height)
    if resolution is None or resolution >= longer:
        return width, height
    return max(1, round(width * resolution / longer)), max(1, round(height * resolution / longer))


def resize_mask(mask: np.ndarray, width: int, height: int) -> np.ndarray:
    """A boolean mask resampled to width x height: its coverage `resize`d, foreground above one half."""
    coverage = torch.from_numpy(np.asarray(mask, dtype=np.float32))[..., None]
    return resize(coverage, height, width).numpy()[..., 0] > 0.5


def resize(image: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """(H, W, C) image resampled to height x width: area average down, bilinear up (no-op when equal)."""
    if tuple(image.shape[:2]) == (height, width):
        return image
    mode = "area" if height <= image.shape[0] else "bilinear"
    out = torch.nn.functional.interpolate(image.permute(2, 0, 1)[None], size=(height, width), mode=mode)
    return out[0].permute(1, 2, 0).contiguous()


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """Inverse sRGB transfer function on values in [0, 1]."""
    c = np.asarray(c, dtype=np.float32)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def linear_to_srgb(c: np.ndarray) -> np.ndarray:
    """sRGB transfer function; input clipped to [0, 1]."""
    c = np.clip(np.asarray(c, dtype=np.float32), 0.0, 1.0)
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * c ** (1 / 2.4) - 0.055).astype(np.float32)


EXIF_ORIENTATION = 0x0112
"""the EXIF tag saying how a camera's stored pixels are to be turned for display"""
@contextmanager
def headers_only() -> Iterator[None]:
    """Pillow without its own decompression-bomb stop, for reading headers: dpi checks the size itself before
    decoding (dpi.io.pixel_bound)."""
    limit = Image.MAX_IMAGE_PIXELS
    Image.MAX_IMAGE_PIXELS = None
    try:
        yield
    finally:
        Image.MAX_IMAGE_PIXELS = limit


PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
PNG_CHUNKS = 100_000
"""most chunks of a PNG looked through for its EXIF"""


def png_exif(path: Path) -> bytes | None:
    """The EXIF block of a PNG's eXIf chunk, found by walking the chunks' headers (nothing decompressed: Pillow's
    getexif decodes the whole image to look past the pixel data); None where it has none."""
    with open(path, "rb") as f:
        if f.read(8) != PNG_SIGNATURE:
            return None
        for _ in range(PNG_CHUNKS):
            head = f.read(8)
            if len(head) < 8:
                return None
            length, kind = int.from_bytes(head[:4], "big"), head[4:]
            if kind == b"eXIf":
                return f.read(length)
            if kind == b"IEND":
                return None
            f.seek(length + 4, os.SEEK_CUR)  # the data and its CRC
    return None


def exif_orientation(path: Path) -> int:
    """A photo's EXIF orientation (1, upright, where it has none or the file has no EXIF), read from the header and
    the EXIF block alone (`png_exif`; a JPEG's APP1 segment), the pixels never decoded."""
    try:
        with headers_only(), Image.open(path) as image:
            if image.format != "PNG":
                return int(image.getexif().get(EXIF_ORIENTATION, 1))
        data = png_exif(path)
        if not data:
            return 1
        exif = Image.Exif()
        exif.load(data)
        return int(exif.get(EXIF_ORIENTATION, 1))
    except (OSError, ValueError, SyntaxError):
        return 1


def upright(values: np.ndarray, orientation: int) -> np.ndarray:
    """`values` (H, W, C) turned as EXIF `orientation` asks, as Pillow's exif_transpose turns an image."""
    ops = {2: lambda a: a[:, ::-1], 3: lambda a: a[::-1, ::-1], 4: lambda a: a[::-1],
           5: lambda a: a.transpose(1, 0, 2), 6: lambda a: np.rot90(a, -1), 7: lambda a: np.rot90(a, 2).transpose(1, 0, 2),
           8: lambda a: np.rot90(a, 1)}
    return np.ascontiguousarray(ops[orientation](values)) if orientation in ops else values


def ldr_header(path: Path) -> tuple[int, int, int]:
    """(width, height, EXIF orientation) of a PNG/JPG as stored, nothing decoded; an unreadable header, or one beyond
    the pixel bound (dpi.io.pixel_bound), is an ImageError naming the file."""
    try:
        with headers_only(), Image.open(path) as image:
            width, height = image.size
    except (OSError, ValueError, SyntaxError):
        raise ImageError(f"{path}: not a readable image (no {path.suffix.lstrip('.')} header)") from None
    problem = size_problem(width, height)
    if problem:
        raise ImageError(f"{path}: {problem}")
    return width, height, exif_orientation(path)


def ldr_header_size(path: Path) -> tuple[int, int]:
    """(width, height) a PNG/JPG's header declares, turned by its EXIF orientation (as `decode_ldr` returns it)
    (`ldr_header`)."""
    width, height, orientation = ldr_header(path)
    return (height, width) if orientation >= 5 else (width, height)


def decode_ldr(path: Path) -> np.ndarray:
    """A PNG/JPG's code values in [0, 1] at its bit depth (8 or 16), (H, W, C): grey (C = 1), RGB or RGBA,
    turned upright by its EXIF orientation (images and masks alike). Its header's size is checked first
    (`ldr_header`)."""
    import cv2

    raw = np.fromfile(path, dtype=np.uint8)
    if raw.size == 0:
        raise ImageError(f"{path}: not a readable image (empty file)")
    orientation = ldr_header(path)[2]
    data = cv2.imdecode(raw, cv2.IMREAD_UNCHANGED)
    if data is None:
        raise ImageError(f"{path}: not a readable image (truncated, or not a {path.suffix.lstrip('.')} file)")
    if data.dtype not in (np.uint8, np.uint16):
        raise ImageError(f"{path}: unsupported pixel type {data.dtype} (use 8 or 16 bits per channel)")
    values = data.astype(np.float32) / np.iinfo(data.dtype).max
    if values.ndim == 2:
        values = values[..., None]
    else:
        values = np.concatenate([values[..., 2::-1], values[..., 3:]], axis=-1)  # OpenCV's BGR(A) -> RGB(A)
    return upright(values, orientation)


RADIANCE_HEADER = 1 << 16
"""most bytes of a Radiance file's header (its text lines and the resolution line) looked through"""
RADIANCE_FORMATS = ("32-bit_rle_rgbe", "32-bit_rle_xyze")


def radiance_header(path: Path, raw: bytes) -> tuple[int, str, list[tuple[str, str, int]]]:
    """A Radiance file's header: where its pixels start, its FORMAT and its resolution line as (sign, axis, count)
    twice (scanlines first: "-Y 512 +X 1024" is the usual top-down, left-to-right order); checked against the pixel
    bound before anything is decoded."""
    if not raw.startswith((b"#?RADIANCE", b"#?RGBE")):
        raise ImageError(f"{path}: not a Radiance HDR file (no #?RADIANCE signature)")
    end = raw.find(b"\n\n", 0, RADIANCE_HEADER)
    stop = raw.find(b"\n", end + 2, RADIANCE_HEADER) if end >= 0 else -1
    if stop < 0:
        raise ImageError(f"{path}: not a readable Radiance HDR file (no end of header and resolution line in its "
                         f"first {RADIANCE_HEADER} bytes)")
    lines = raw[:end].decode("latin-1").splitlines()
    formats = [line.split("=", 1)[1].strip() for line in lines if line.startswith("FORMAT=")]
    form = formats[-1] if formats else RADIANCE_FORMATS[0]
    if form not in RADIANCE_FORMATS:
        raise ImageError(f"{path}: Radiance FORMAT={form}: dpi reads {' and '.join(RADIANCE_FORMATS)}")
    tokens = raw[end + 2:stop].decode("latin-1").split()
    try:
        axes = [(tokens[i][0], tokens[i][1], int(tokens[i + 1])) for i in (0, 2)]
    except (IndexError, ValueError):
        axes = []
    if len(tokens) != 4 or len(axes) != 2 or {a[1] for a in axes} != {"X", "Y"} or \
            any(a[0] not in "+-" for a in axes):
        raise ImageError(f"{path}: not a readable Radiance HDR file (resolution line {raw[end + 2:stop][:40]!r})")
    problem = size_problem(axes[1][2], axes[0][2]) if axes[0][1] == "Y" else size_problem(axes[0][2], axes[1][2])
    if problem:
        raise ImageError(f"{path}: {problem}")
    return stop + 1, form, axes


def read_hdr(path: str | os.PathLike) -> np.ndarray:
    """Linear RGB float32 (H, W, 3) of a Radiance .hdr file: its header read and bounded first (`radiance_header`),
    the run-length pixels decoded by OpenCV, then turned by the resolution line's orientation and an XYZE file's
    colours converted to RGB; an unreadable file is an ImageError naming it."""
    import cv2

    from dpi.io.exr import XYZ_TO_RGB

    path = Path(path)
    if not path.is_file():
        raise ImageError(f"{path}: image file does not exist")
    raw = path.read_bytes()
    start, form, axes = radiance_header(path, raw)
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)  # a truncated file is said once, below
    (s1, a1, n1), (s2, _, n2) = axes
    usual = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n" + f"-Y {n1} +X {n2}\n".encode()  # scanlines as stored
    data = cv2.imdecode(np.frombuffer(usual + raw[start:], np.uint8), cv2.IMREAD_ANYDEPTH | cv2.IMREAD_COLOR)
    if data is None or data.dtype != np.float32 or data.shape[:2] != (n1, n2):
        raise ImageError(f"{path}: not a readable Radiance HDR file (truncated pixels)")
    image = data[..., ::-1]
    if a1 == "X":  # scanlines are columns
        image = image.transpose(1, 0, 2)
    y_sign, x_sign = (s1, s2) if a1 == "Y" else (s2, s1)
    image = image[::-1] if y_sign == "+" else image  # +Y: the bottom scanline first
    image = image[:, ::-1] if x_sign == "-" else image
    if form == "32-bit_rle_xyze":
        image = np.clip(image @ XYZ_TO_RGB.T, 0, None)
    return np.ascontiguousarray(image, dtype=np.float32)


def hdr_bytes(linear: np.ndarray) -> bytes:
    """A linear RGB float image (H, W, 3) encoded as a Radiance .hdr file (OpenCV's RGBE writer)."""
    import cv2

    ok, data = cv2.imencode(".hdr", np.ascontiguousarray(np.asarray(linear, np.float32)[..., 2::-1]))
    if not ok:
        raise ImageError("could not encode the image as Radiance HDR")
    return data.tobytes()


def write_hdr(path: str | os.PathLike, linear: np.ndarray) -> None:
    """Write a linear RGB float image as a Radiance .hdr file, atomically."""
    data = hdr_bytes(linear)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Linear RGB float32 (H, W, 3) from an sRGB PNG/JPG or a linear EXR; NaN/Inf is an error."""
    path = Path(path)
    suffix = path.suffix.lower()
    if not path.is_file():
        raise ImageError(f"{path}: image file does not exist")
    if suffix in HDR_SUFFIXES:
        try:
            image = read_exr(path)
        except EXRError as exc:
            raise ImageError(str(exc)) from exc
    elif suffix in LDR_SUFFIXES:
        values = decode_ldr(path)
        image = srgb_to_linear(values[..., :3] if values.shape[-1] >= 3 else values[..., :1])
    else:
        raise ImageError(f"{path}: unsupported image format (use {', '.join(IMAGE_SUFFIXES)})")
    if image.shape[-1] == 1:
        image = np.repeat(image, 3, axis=-1)
    if not np.isfinite(image).all():
        raise ImageError(f"{path}: image contains NaN or Inf values")
    if (image < 0).any():
        raise ImageError(f"{path}: image contains negative radiance values")
    return image


def mask_values(path: str | os.PathLike) -> np.ndarray:
    """A mask file's values (H, W) in [0, 1] before the threshold: from a PNG/JPG (8 or 16 bits) the alpha channel
    where it varies (a cut-out), else the grey value (Rec. 601 luma of RGB): an opaque alpha, as many editors save a
    black-and-white mask, says nothing; from an EXR its first channel."""
    path = Path(path)
    if not path.is_file():
        raise ImageError(f"{path}: mask file does not exist")
    if path.suffix.lower() in HDR_SUFFIXES:
        try:
            return read_exr(path)[..., 0]
        except EXRError as exc:
            raise ImageError(str(exc)) from exc
    values = decode_ldr(path)
    colour, alpha = (values[..., :3], values[..., 3]) if values.shape[-1] == 4 else (values, None)  # grey + alpha: RGBA
    if alpha is not None and alpha.min() < alpha.max():
        return alpha
    return colour @ np.array(REC601_LUMA, np.float32) if colour.shape[-1] == 3 else colour[..., 0]


def read_mask(path: str | os.PathLike) -> np.ndarray:
    """Boolean foreground mask (H, W): `mask_values` above 0.5."""
    return mask_values(path) > 0.5


def to_uint8(linear: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    """8-bit sRGB encoding of a linear image (clipped), after multiplying by `exposure`."""
    return np.round(linear_to_srgb(np.asarray(linear) * exposure) * 255).astype(np.uint8)


def write_srgb(path: str | os.PathLike, linear: np.ndarray, exposure: float = 1.0) -> None:
    """Write a linear RGB image as 8-bit sRGB, atomically: a JPEG (quality 92) for .jpg/.jpeg, else a PNG."""
    jpeg = Path(path).suffix.lower() in (".jpg", ".jpeg")
    with atomic_path(path) as tmp:
        Image.fromarray(to_uint8(linear, exposure)).save(tmp, format="JPEG" if jpeg else "PNG",
                                                         **({"quality": 92} if jpeg else {}))


def write_srgb_alpha(path: str | os.PathLike, linear: np.ndarray, alpha: np.ndarray) -> None:
    """Write a linear RGB image and a coverage in [0, 1] as an 8-bit sRGB RGBA PNG (a cut-out), atomically."""
    rgba = np.concatenate([to_uint8(linear), np.round(np.clip(alpha, 0, 1) * 255).astype(np.uint8)[..., None]], -1)
    with atomic_path(path) as tmp:
        Image.fromarray(rgba, mode="RGBA").save(tmp, format="PNG")


def write_mask(path: str | os.PathLike, mask: np.ndarray) -> None:
    """Write a boolean mask as an 8-bit PNG (255 = foreground), atomically."""
    with atomic_path(path) as tmp:
        Image.fromarray(np.where(mask, 255, 0).astype(np.uint8)).save(tmp, format="PNG")


def tonemap(radiance: np.ndarray) -> np.ndarray:
    """Reinhard L / (1 + L): HDR radiance into [0, 1) for image metrics."""
    radiance = np.clip(radiance, 0, None)
    return radiance / (1.0 + radiance)
