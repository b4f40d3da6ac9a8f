"""The one bound on the pixels an image file may declare, checked on its header before anything decodes it: a small
file that declares a huge image (a corrupt header, a decompression bomb) stops at once, whatever its format."""

from __future__ import annotations

MAX_IMAGE_PIXELS = 1 << 27
"""most pixels an image file (PNG, JPG, EXR windows, Radiance) may declare: 134 megapixels, more than a 100-megapixel
camera back's or a 16k x 8k panorama's"""


def size_problem(width: int, height: int) -> str | None:
    """Why an image of width x height may not be decoded (None: it may): not positive, or beyond MAX_IMAGE_PIXELS."""
    if width <= 0 or height <= 0:
        return f"declares {width}x{height} px (a corrupt header)"
    if width * height > MAX_IMAGE_PIXELS:
        return (f"declares {width}x{height} px, more than the {MAX_IMAGE_PIXELS} pixels dpi decodes (a corrupt "
                "header, or an image far larger than a photo)")
    return None
