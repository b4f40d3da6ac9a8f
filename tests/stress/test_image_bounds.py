"""Image headers are bounded before anything decodes them, and the readers take what the formats allow (issue 91).

Each bad file is a few hundred bytes that declares a huge image or an unusual but valid layout; the readers answer
with one error naming the file and the cause, or with the image the file holds."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
import OpenEXR
import pytest
from PIL import Image

from dpi.io.exr import XYZ_TO_RGB, EXRError, read_exr
from dpi.io.images import ImageError, decode_ldr, exif_orientation, hdr_bytes, ldr_header_size, read_hdr, read_image
from dpi.io.pixel_bound import MAX_IMAGE_PIXELS

HUGE = 100_000


def png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_declaring(width: int, height: int, exif_after_pixels: bool = False) -> bytes:
    """A tiny PNG whose header declares width x height (its pixel data one row), optionally with an eXIf chunk after
    the pixel data (where Pillow's getexif decodes the whole image to find it)."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    pixels = zlib.compress(b"\x00" + b"\x80" * 3 * 4)
    exif = Image.Exif()
    exif[0x0112] = 6
    tail = png_chunk(b"eXIf", exif.tobytes()) if exif_after_pixels else b""
    return (b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr) + png_chunk(b"IDAT", pixels) + tail
            + png_chunk(b"IEND", b""))


def jpeg_declaring(tmp_path: Path, width: int, height: int) -> bytes:
    """A small JPEG with its frame header's size patched to width x height."""
    path = tmp_path / "small.jpg"
    Image.new("RGB", (8, 8), (90, 120, 150)).save(path, quality=90)
    data = bytearray(path.read_bytes())
    sof = data.index(b"\xff\xc0")
    data[sof + 5:sof + 9] = struct.pack(">HH", height, width)
    return bytes(data)


def exr_with(path: Path, channels: dict[str, np.ndarray], **header) -> Path:
    OpenEXR.File({"type": OpenEXR.scanlineimage, **header}, channels).write(str(path))
    return path


def corners(x0: int, y0: int, x1: int, y1: int) -> tuple[np.ndarray, np.ndarray]:
    return np.array([x0, y0], np.int32), np.array([x1, y1], np.int32)


ONES = np.ones((4, 5), np.float32)


@pytest.mark.parametrize("name, make", [
    ("png_huge.png", lambda tmp: png_declaring(HUGE, HUGE)),
    ("png_huge_exif_after_pixels.png", lambda tmp: png_declaring(HUGE, HUGE, exif_after_pixels=True)),
    ("png_tall.png", lambda tmp: png_declaring(1, MAX_IMAGE_PIXELS + 1)),
    ("jpeg_huge.jpg", lambda tmp: jpeg_declaring(tmp, 60_000, 60_000)),
    ("png_wide.png", lambda tmp: png_declaring(MAX_IMAGE_PIXELS + 1, 1)),
])
def test_ldr_headers_beyond_the_bound_are_refused_before_decoding(tmp_path, name, make):
    path = tmp_path / name
    path.write_bytes(make(tmp_path))
    for read in (ldr_header_size, decode_ldr, read_image):
        with pytest.raises(ImageError, match="declares") as caught:
            read(path)
        assert str(caught.value).startswith(str(path))


def test_a_png_exif_after_its_pixels_is_read_without_decoding(tmp_path):
    path = tmp_path / "turned.png"
    path.write_bytes(png_declaring(4, 1, exif_after_pixels=True))
    assert exif_orientation(path) == 6
    assert ldr_header_size(path) == (1, 4)  # turned a quarter: as decode_ldr returns it
    assert decode_ldr(path).shape == (4, 1, 3)


@pytest.mark.parametrize("name, header, words", [
    ("display_huge.exr", {"displayWindow": corners(0, 0, HUGE - 1, HUGE - 1)}, "display window declares"),
    ("display_wide.exr", {"displayWindow": corners(0, 0, MAX_IMAGE_PIXELS, 0)}, "display window declares"),
    ("data_outside.exr", {"dataWindow": corners(100, 100, 104, 103), "displayWindow": corners(0, 0, 9, 9)},
     "lies outside its display window"),
    ("data_left.exr", {"dataWindow": corners(-20, 0, -16, 3), "displayWindow": corners(0, 0, 9, 9)},
     "lies outside its display window"),
])
def test_exr_windows_are_bounded_and_must_overlap(tmp_path, name, header, words):
    path = exr_with(tmp_path / name, {"R": ONES, "G": ONES, "B": ONES}, **header)
    with pytest.raises(EXRError, match=words) as caught:
        read_exr(path)
    assert str(caught.value).startswith(str(path))


def test_an_exr_data_window_huge_in_a_small_display_is_refused_from_its_header(tmp_path):
    # the header alone is patched: a real file of that data window would hold gigabytes
    path = exr_with(tmp_path / "data_huge.exr", {"R": ONES, "G": ONES, "B": ONES})
    raw = bytearray(path.read_bytes())
    at = raw.index(b"dataWindow\x00box2i\x00") + len(b"dataWindow\x00box2i\x00") + 4
    raw[at:at + 16] = struct.pack("<iiii", 0, 0, HUGE - 1, HUGE - 1)
    path.write_bytes(bytes(raw))
    with pytest.raises(EXRError, match="data window declares"):
        read_exr(path)


def test_exr_xyz_channels_are_converted_to_rgb(tmp_path):
    rgb = np.array([0.2, 0.5, 0.9], np.float32)
    xyz = np.linalg.solve(XYZ_TO_RGB.astype(np.float64), rgb.astype(np.float64))
    path = exr_with(tmp_path / "xyz.exr", {n: ONES * np.float32(v) for n, v in zip("XYZ", xyz)})
    assert read_exr(path)[2, 3] == pytest.approx(rgb, abs=1e-5)


def test_a_multipart_exr_is_read_from_its_colour_part(tmp_path):
    path = tmp_path / "multipart.exr"
    parts = [OpenEXR.Part({"type": OpenEXR.scanlineimage}, {"Z": ONES * 7}, name="depth"),
             OpenEXR.Part({"type": OpenEXR.scanlineimage}, {"R": ONES, "G": ONES * 2, "B": ONES * 3}, name="beauty")]
    OpenEXR.File(parts).write(str(path))
    assert read_exr(path)[0, 0] == pytest.approx([1, 2, 3])


@pytest.mark.parametrize("channels, words", [
    ({"Z": ONES}, "hold no image"),
    ({"Y": ONES, "RY": ONES * 0, "BY": ONES * 0}, "luminance-chroma"),
])
def test_exr_channels_without_an_image_are_named(tmp_path, channels, words):
    path = exr_with(tmp_path / "odd.exr", channels)
    with pytest.raises(EXRError, match=words):
        read_exr(path)


IMAGE = (np.arange(6 * 10 * 3, dtype=np.float32).reshape(6, 10, 3) + 1) / 40


def radiance(image: np.ndarray, resolution: str, form: str = "32-bit_rle_rgbe") -> bytes:
    """`image` stored scanline by scanline as given, under another resolution line and format."""
    data = hdr_bytes(np.ascontiguousarray(image))
    usual = f"-Y {image.shape[0]} +X {image.shape[1]}\n".encode()
    return data.replace(usual, f"{resolution}\n".encode()).replace(b"32-bit_rle_rgbe", form.encode())


@pytest.mark.parametrize("resolution, stored", [
    ("-Y 6 +X 10", IMAGE),
    ("+Y 6 +X 10", IMAGE[::-1]),
    ("-Y 6 -X 10", IMAGE[:, ::-1]),
    ("+X 10 -Y 6", IMAGE.transpose(1, 0, 2)),
    ("-X 10 +Y 6", IMAGE[::-1, ::-1].transpose(1, 0, 2)),
])
def test_radiance_orientations_read_upright(tmp_path, resolution, stored):
    path = tmp_path / "turned.hdr"
    path.write_bytes(radiance(stored, resolution))
    assert read_hdr(path) == pytest.approx(IMAGE, rel=0.01)


def test_radiance_xyze_is_converted_to_rgb(tmp_path):
    path = tmp_path / "xyze.hdr"
    path.write_bytes(radiance(IMAGE, "-Y 6 +X 10", "32-bit_rle_xyze"))
    rgb = np.clip(read_hdr(tmp_path / "xyze.hdr"), 0, None)
    expected = np.clip(read_hdr_rgbe(tmp_path, IMAGE) @ XYZ_TO_RGB.T, 0, None)
    assert rgb == pytest.approx(expected, rel=1e-5, abs=1e-6)


def read_hdr_rgbe(tmp_path: Path, image: np.ndarray) -> np.ndarray:
    path = tmp_path / "plain.hdr"
    path.write_bytes(radiance(image, "-Y 6 +X 10"))
    return read_hdr(path)


@pytest.mark.parametrize("name, data, words", [
    ("huge.hdr", b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 100000 +X 100000\n" + bytes(64), "declares"),
    ("zero.hdr", b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 0 +X 100\n" + bytes(64), "declares"),
    ("format.hdr", b"#?RADIANCE\nFORMAT=bits\n\n-Y 2 +X 2\n" + bytes(64), "FORMAT=bits"),
    ("no_resolution.hdr", b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n", "no end of header"),
    ("bad_resolution.hdr", b"#?RADIANCE\n\n-Y 2 +Y 2\n" + bytes(64), "resolution line"),
    ("not_radiance.hdr", b"P6 2 2 255\n" + bytes(12), "RADIANCE signature"),
    ("truncated.hdr", None, "truncated"),
])
def test_bad_radiance_files_are_named_before_decoding(tmp_path, name, data, words):
    path = tmp_path / name
    path.write_bytes(data if data is not None else radiance(IMAGE, "-Y 6 +X 10")[:-40])
    with pytest.raises(ImageError, match=words) as caught:
        read_hdr(path)
    assert str(caught.value).startswith(str(path))
