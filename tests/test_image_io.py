"""EXR and LDR image I/O: round trips, known sRGB values, masks, and errors that name the file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenEXR
import pytest
from PIL import Image

from dpi.io.exr import EXRError, read_exr, write_exr
from dpi.io.images import (ImageError, linear_to_srgb, read_image, read_mask, srgb_to_linear, to_uint8, write_mask,
                           write_srgb)


def ramp(height: int = 4, width: int = 6) -> np.ndarray:
    """A (H, W, 3) HDR test image with values above 1."""
    return np.linspace(0.0, 8.0, height * width * 3, dtype=np.float32).reshape(height, width, 3)


@pytest.mark.parametrize("half", [False, True])
def test_exr_round_trip(tmp_path, half):
    """write_exr -> read_exr returns the data (exactly for float32, to half precision for half)."""
    write_exr(tmp_path / "a.exr", ramp(), half=half)
    back = read_exr(tmp_path / "a.exr")
    assert back.dtype == np.float32 and back.shape == (4, 6, 3)
    np.testing.assert_allclose(back, ramp(), rtol=1e-3 if half else 0)


def test_single_channel_exr_reads_as_one_channel(tmp_path):
    """A (H, W) array is stored as a Y channel and read back as (H, W, 1)."""
    write_exr(tmp_path / "y.exr", ramp()[..., 0])
    np.testing.assert_array_equal(read_exr(tmp_path / "y.exr"), ramp()[..., :1])


def test_data_window_is_placed_inside_display_window(tmp_path):
    """Pixels outside a smaller data window read as 0; the ones inside land at their position."""
    data = np.arange(6, dtype=np.float32).reshape(2, 3)
    window = (np.array([1, 2], np.int32), np.array([3, 3], np.int32))
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage, "dataWindow": window,
              "displayWindow": (np.array([0, 0], np.int32), np.array([4, 4], np.int32))}
    with OpenEXR.File(header, {c: data for c in "RGB"}) as exr:
        exr.write(str(tmp_path / "w.exr"))
    image = read_exr(tmp_path / "w.exr")
    expected = np.zeros((5, 5), np.float32)
    expected[2:4, 1:4] = data
    np.testing.assert_array_equal(image[..., 1], expected)


def test_write_exr_refuses_nan_and_leaves_no_file(tmp_path):
    """NaN is never written; the failed write leaves nothing behind."""
    bad = ramp()
    bad[0, 0, 0] = np.nan
    with pytest.raises(EXRError, match=r"bad\.exr.*NaN"):
        write_exr(tmp_path / "bad.exr", bad)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("content", [None, b"not an exr"])
def test_read_exr_errors_name_the_file(tmp_path, content):
    """Missing and corrupt EXRs raise EXRError starting with the path."""
    path = tmp_path / "x.exr"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(EXRError, match=r"^.*x\.exr: "):
        read_exr(path)


def test_srgb_curve_known_values_and_inverse():
    """sRGB decoding matches the standard's values and inverts the encoding."""
    np.testing.assert_allclose(srgb_to_linear(np.array([0.0, 0.04045, 0.5, 1.0])),
                               [0.0, 0.04045 / 12.92, 0.2140411, 1.0], rtol=1e-5)
    x = np.linspace(0, 1, 101, dtype=np.float32)
    np.testing.assert_allclose(srgb_to_linear(linear_to_srgb(x)), x, atol=1e-6)


def test_png_round_trip_within_quantisation(tmp_path):
    """write_srgb stores sRGB 8-bit; read_image decodes back to linear within one code value."""
    linear = np.clip(ramp() / 8.0, 0, 1)
    write_srgb(tmp_path / "a.png", linear)
    back = read_image(tmp_path / "a.png")
    assert back.shape == linear.shape and back.dtype == np.float32
    np.testing.assert_allclose(linear_to_srgb(back), linear_to_srgb(linear), atol=0.5 / 255 + 1e-6)
    assert to_uint8(np.array([0.5]), exposure=2.0)[0] == 255


def test_grey_exr_reads_as_rgb(tmp_path):
    """read_image always returns three channels."""
    write_exr(tmp_path / "g.exr", ramp()[..., 0])
    assert read_image(tmp_path / "g.exr").shape == (4, 6, 3)


@pytest.mark.parametrize("name, data, keyword", [
    ("neg.exr", -ramp(), "negative"),
    ("missing.png", None, "does not exist"),
    ("bad.png", b"junk", "not a readable image"),
    ("img.tiff", b"junk", "unsupported"),
])
def test_read_image_errors_name_the_file(tmp_path, name, data, keyword):
    """Each unusable image raises ImageError with its path and the problem."""
    path = tmp_path / name
    if isinstance(data, np.ndarray):
        write_exr(path, data)
    elif data is not None:
        path.write_bytes(data)
    with pytest.raises(ImageError, match=rf"{name}: .*{keyword}"):
        read_image(path)


def test_masks_from_grey_alpha_and_exr(tmp_path):
    """Masks threshold grey PNGs, prefer an alpha channel, and read EXRs at 0.5."""
    mask = np.zeros((4, 6), bool)
    mask[1:3, 2:5] = True
    write_mask(tmp_path / "m.png", mask)
    np.testing.assert_array_equal(read_mask(tmp_path / "m.png"), mask)
    rgba = np.zeros((4, 6, 4), np.uint8)
    rgba[..., 3] = np.where(mask, 255, 0)
    Image.fromarray(rgba, "RGBA").save(tmp_path / "a.png")
    np.testing.assert_array_equal(read_mask(tmp_path / "a.png"), mask)
    write_exr(tmp_path / "m.exr", mask.astype(np.float32))
    np.testing.assert_array_equal(read_mask(tmp_path / "m.exr"), mask)


def test_missing_mask_names_the_file(tmp_path: Path):
    """A missing mask raises ImageError naming it."""
    with pytest.raises(ImageError, match=r"nomask\.png: mask file does not exist"):
        read_mask(tmp_path / "nomask.png")


def test_jpeg_written_as_srgb_reads_back_close_to_the_png(tmp_path):
    rng = np.random.default_rng(0)
    smooth = np.repeat(np.repeat(rng.uniform(0.05, 0.8, (8, 8, 3)), 8, 0), 8, 1).astype(np.float32)
    write_srgb(tmp_path / "a.png", smooth)
    write_srgb(tmp_path / "a.jpg", smooth)
    assert Image.open(tmp_path / "a.jpg").format == "JPEG"
    png, jpg = read_image(tmp_path / "a.png"), read_image(tmp_path / "a.jpg")
    assert np.abs(linear_to_srgb(jpg) - linear_to_srgb(png)).mean() < 0.04  # quality 92, 4:2:0 chroma at block edges
