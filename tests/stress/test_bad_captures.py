"""Bad and unusual capture inputs with known answers: PNGs of every bit depth and colour type read as
their 8-bit copy does; truncated files, non-rigid or non-finite cameras, bad intrinsics, values of the
wrong type (naming frame, key, value and type), broken meshes, images without signal or under 8 px,
depth-only EXRs, bad ground truth and bad scene.yaml each stop with one CaptureError naming the file,
and leave no capture.json behind."""

from __future__ import annotations

import json
import re
import shutil
import warnings
from pathlib import Path
from typing import Callable

import cv2
import numpy as np
import pytest
import trimesh
from capture_helpers import NAMES, SIZE, edit_transforms, make_capture, raw_exr

from dpi.capture import CaptureError, CaptureWarning, inspect_capture, load_capture, read_scene_options
from dpi.capture.cameras import to_mitsuba
from dpi.capture.folder import check_signal
from dpi.io.images import read_image, read_mask, srgb_to_linear
from dpi.preprocess.derive import normalise_capture
from dpi.solve.exposure import capture_exposure

RNG = np.random.default_rng(7)
CODES = RNG.integers(0, 256, (SIZE, SIZE, 3), dtype=np.uint8)
"""8-bit code values of the reference copy; the 16-bit versions hold code * 257 (the same fraction of white)"""


def write_cv2(path: Path, codes: np.ndarray) -> Path:
    """Write RGB(A) or grey code values (uint8 or uint16) as a PNG through OpenCV (BGR order on disk)."""
    data = codes[..., [2, 1, 0, *range(3, codes.shape[-1])]] if codes.ndim == 3 else codes
    assert cv2.imwrite(str(path), data)
    return path


def grey(codes: np.ndarray) -> np.ndarray:
    """The first channel, as a grey image."""
    return codes[..., 0]


def with_alpha(codes: np.ndarray) -> np.ndarray:
    """Codes with an opaque alpha channel of the same depth."""
    return np.concatenate([codes, np.full(codes.shape[:2] + (1,), np.iinfo(codes.dtype).max, codes.dtype)], -1)


def pil_save(mode: str) -> Callable[[Path, np.ndarray], Path]:
    """A writer that saves 8-bit RGB codes through PIL in another mode (exact palette, 1-bit, grey + alpha)."""
    def save(path: Path, codes: np.ndarray) -> Path:
        from PIL import Image

        rgb = Image.fromarray(codes)
        (rgb.convert("P", palette=Image.Palette.ADAPTIVE) if mode == "P" else rgb.convert(mode)).save(path)
        return path
    return save


WIDE = CODES.astype(np.uint16) * 257
GREY3 = np.repeat(CODES[..., :1], 3, -1)
BLACK_WHITE = np.where(GREY3 > 127, 255, 0).astype(np.uint8)
FOUR_COLOURS = CODES // 64 * 85
VARIANTS = {  # name: (write the variant, the 8-bit RGB codes it must read as)
    "16-bit grey": (lambda p: write_cv2(p, grey(WIDE)), GREY3),
    "16-bit RGB": (lambda p: write_cv2(p, WIDE), CODES),
    "16-bit RGBA": (lambda p: write_cv2(p, with_alpha(WIDE)), CODES),
    "8-bit grey": (lambda p: write_cv2(p, grey(CODES)), GREY3),
    "8-bit RGBA": (lambda p: write_cv2(p, with_alpha(CODES)), CODES),
    "8-bit grey + alpha": (lambda p: pil_save("LA")(p, GREY3), GREY3),
    "palette": (lambda p: pil_save("P")(p, FOUR_COLOURS[..., :1].repeat(3, -1)), FOUR_COLOURS[..., :1].repeat(3, -1)),
    "1-bit": (lambda p: pil_save("1")(p, BLACK_WHITE), BLACK_WHITE),
}


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_png_variants_read_as_their_8_bit_copy(tmp_path, variant):
    """Every PNG bit depth and colour type decodes to the linear values of its 8-bit RGB copy."""
    write, codes = VARIANTS[variant]
    copy = write_cv2(tmp_path / "copy.png", codes)
    np.testing.assert_allclose(read_image(write(tmp_path / "variant.png")), read_image(copy), atol=1e-6)


def test_16_bit_precision_is_kept(tmp_path):
    """A 16-bit code between two 8-bit ones reads at its own value (1000 / 65535 is not a multiple of 1/255)."""
    values = read_image(write_cv2(tmp_path / "g.png", np.full((4, 4), 1000, np.uint16)))
    assert values[0, 0, 0] == pytest.approx((1000 / 65535) / 12.92, rel=1e-6)


def test_16_bit_grey_capture_reads_like_its_8_bit_copy(tmp_path):
    """The reported bug: a 16-bit grey capture read every pixel as 1.0; it must read as the 8-bit grey copy."""
    shades = np.full((SIZE, SIZE), 95, np.uint8)  # 0.115 linear
    shades[:2] = 40
    for depth, codes in (("8", shades), ("16", shades.astype(np.uint16) * 257)):
        root = make_capture(tmp_path / depth)
        for name in NAMES[:2]:
            write_cv2(root / "images" / f"{name}.png", codes)
        first = load_capture(root).views[0].image
        assert float(np.median(read_image(first))) == pytest.approx(0.1144, abs=2e-4)
    np.testing.assert_array_equal(read_image(tmp_path / "8" / "images" / "r_0.png"),
                                  read_image(tmp_path / "16" / "images" / "r_0.png"))


def test_16_bit_mask_matches_its_8_bit_copy(tmp_path):
    """A 16-bit mask thresholds at half of white, as the 8-bit one does at 127."""
    mask = np.where(CODES[..., 0] > 127, 255, 0).astype(np.uint8)
    np.testing.assert_array_equal(read_mask(write_cv2(tmp_path / "m16.png", mask.astype(np.uint16) * 257)),
                                  read_mask(write_cv2(tmp_path / "m8.png", mask)))


# --- one CaptureError naming the file -------------------------------------------------------------


def truncate(path: Path, keep: float) -> None:
    """Cut a file to a fraction of its bytes."""
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])


def set_frame(key: str, value, frame: int = 0) -> Callable[[Path], None]:
    """An edit of transforms.json setting one key of one frame."""
    def edit(root: Path) -> None:
        edit_transforms(root, lambda data: data["frames"][frame].__setitem__(key, value))
    return edit


def set_rotation(transform: Callable[[np.ndarray], np.ndarray]) -> Callable[[Path], None]:
    """An edit of transforms.json replacing frame 0's camera-to-world matrix by transform(matrix)."""
    def edit(root: Path) -> None:
        def change(data: dict) -> None:
            data["frames"][0]["transform_matrix"] = transform(np.array(data["frames"][0]["transform_matrix"])).tolist()
        edit_transforms(root, change)
    return edit


def with_columns(scales: tuple[float, float, float]) -> Callable[[np.ndarray], np.ndarray]:
    """The rotation's columns multiplied by scales (0: singular, equal columns: rank-deficient, -1: reflection)."""
    def change(c2w: np.ndarray) -> np.ndarray:
        c2w[:3, :3] = c2w[:3, :3] * np.array(scales)
        return c2w
    return change


def sheared(c2w: np.ndarray) -> np.ndarray:
    """The first rotation column tilted towards the second."""
    c2w[:3, 0] += 0.3 * c2w[:3, 1]
    return c2w


def rank_deficient(c2w: np.ndarray) -> np.ndarray:
    """Two equal rotation columns."""
    c2w[:3, 2] = c2w[:3, 1]
    return c2w


def entry(row: int, col: int, value: float) -> Callable[[np.ndarray], np.ndarray]:
    """One matrix entry replaced."""
    def change(c2w: np.ndarray) -> np.ndarray:
        c2w[row, col] = value
        return c2w
    return change


def nerf_synthetic(angle: float) -> Callable[[Path], None]:
    """transforms.json with only camera_angle_x for the intrinsics (NeRF-synthetic)."""
    def edit(root: Path) -> None:
        def change(data: dict) -> None:
            for frame in data["frames"]:
                for key in ("fl_x", "fl_y", "cx", "cy"):
                    frame.pop(key)
            data["camera_angle_x"] = angle
        edit_transforms(root, change)
    return edit


def write_mesh(vertices: np.ndarray, encoding: str) -> Callable[[Path], None]:
    """Replace mesh.ply by a tetrahedron-like mesh with the given vertices (ascii or binary PLY)."""
    def edit(root: Path) -> None:
        mesh = trimesh.Trimesh(vertices, [[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]], process=False)
        (root / "mesh.ply").write_bytes(mesh.export(file_type="ply", encoding=encoding))
    return edit


TETRA = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
NAN_TETRA = np.where(np.arange(12).reshape(4, 3) == 4, np.nan, TETRA)


def obj_mesh(text: str) -> Callable[[Path], None]:
    """Replace mesh.ply by an OBJ file with the given text."""
    def edit(root: Path) -> None:
        (root / "mesh.ply").unlink()
        (root / "mesh.obj").write_text(text)
    return edit


def ascii_ply_with_faces(faces: str) -> Callable[[Path], None]:
    """An ASCII PLY of three vertices with the given face lines."""
    def edit(root: Path) -> None:
        (root / "mesh.ply").write_text(
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
            f"element face {faces.count(chr(10))}\nproperty list uchar int vertex_indices\nend_header\n"
            "0 0 0\n1 0 0\n0 1 0\n" + faces)
    return edit


def fill_png(name: str, codes: int) -> Callable[[Path], None]:
    """An 8-bit PNG image of one code value everywhere."""
    return lambda root: write_cv2(root / "images" / f"{name}.png", np.full((SIZE, SIZE, 3), codes, np.uint8))


def set_matrix_entry(value) -> Callable[[Path], None]:
    """An edit of transforms.json putting `value` (of any JSON type) into frame 0's matrix at row 0, column 3."""
    return lambda root: edit_transforms(root, lambda data: data["frames"][0]["transform_matrix"][0].__setitem__(3, value))


def exr_channels(path: str, names: str) -> Callable[[Path], None]:
    """Replace an EXR of the capture by one whose channels have these one-letter names (e.g. "Z": depth only)."""
    def edit(root: Path) -> None:
        import OpenEXR

        channels = {n: np.full((SIZE, 2 * SIZE if "envmap" in path else SIZE), 0.5, np.float32) for n in names}
        with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, channels) as exr:
            exr.write(str(root / path))
    return edit


def gt_values(name: str, shape: tuple[int, ...], value: float) -> Callable[[Path], None]:
    """Replace gt/{name}.exr by a constant map (unchecked, through raw_exr)."""
    return lambda root: raw_exr(root / "gt" / f"{name}.exr", np.full(shape, value))


def png_bomb(path: Path, width: int = 20000, height: int = 20000) -> None:
    """A PNG of a few hundred bytes whose header declares width x height (one row of data)."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(b"\0" * (1 + 3 * width)))
                     + chunk(b"IEND", b""))


BROKEN = {  # case: (break the capture, file the message starts with, words it contains)
    "png declaring 20000x20000": (lambda r: png_bomb(r / "images" / "r_1.png"), "r_1.png", "20000x20000"),
    "truncated exr (half)": (lambda r: truncate(r / "images" / "r_2.exr", 0.5), "r_2.exr", "not a readable EXR"),
    "truncated exr (last byte)": (lambda r: truncate(r / "images" / "r_3.exr", 0.999), "r_3.exr", "not a readable EXR"),
    "truncated exr (header)": (lambda r: truncate(r / "images" / "r_2.exr", 0.05), "r_2.exr", "not a readable EXR"),
    "empty exr": (lambda r: truncate(r / "images" / "r_2.exr", 0), "r_2.exr", "not a readable EXR"),
    "truncated gt exr": (lambda r: truncate(r / "gt" / "envmap.exr", 0.5), "envmap.exr", "not a readable EXR"),
    "truncated png": (lambda r: truncate(r / "images" / "r_0.png", 0.5), "r_0.png", "not a readable image"),
    "empty png": (lambda r: truncate(r / "images" / "r_1.png", 0), "r_1.png", "not a readable image"),
    "truncated mask": (lambda r: truncate(r / "masks" / "r_1.png", 0.5), "r_1.png", "not a readable image"),
    "singular rotation": (set_rotation(with_columns((0, 0, 0))), "transforms.json", "not orthonormal"),
    "rank-deficient rotation": (set_rotation(rank_deficient), "transforms.json", "not orthonormal"),
    "scaled rotation": (set_rotation(with_columns((2, 2, 2))), "transforms.json", "scaled, sheared or singular"),
    "slightly scaled rotation": (set_rotation(with_columns((1.01, 1, 1))), "transforms.json", "not orthonormal"),
    "sheared rotation": (set_rotation(sheared), "transforms.json", "not orthonormal"),
    "reflection": (set_rotation(with_columns((-1, 1, 1))), "transforms.json", "reflection"),
    "nan in matrix": (set_rotation(entry(1, 1, np.nan)), "transforms.json", "finite"),
    "inf translation": (set_rotation(entry(2, 3, np.inf)), "transforms.json", "finite"),
    "bad last row": (set_rotation(entry(3, 0, 0.5)), "transforms.json", "last row"),
    "focal 0": (set_frame("fl_x", 0.0), "transforms.json", "focal length must be positive"),
    "negative focal": (set_frame("fl_x", -20.0), "transforms.json", "focal length must be positive"),
    "negative fl_y": (set_frame("fl_y", -20.0), "transforms.json", "focal length must be positive"),
    "nan focal": (set_frame("fl_x", np.nan), "transforms.json", "intrinsics must be finite"),
    "nan principal point": (set_frame("cx", np.nan), "transforms.json", "intrinsics must be finite"),
    "non-square pixels": (set_frame("fl_y", 30.0), "transforms.json", "pixels must be square"),
    "focal not a number": (set_frame("fl_x", "wide"), "transforms.json", 'frame 0 (images/r_0.png): fl_x must be a number, got "wide" (a string)'),
    "zero width": (set_frame("w", 0), "transforms.json", "image size must be positive, got 0x8"),
    "camera_angle_x 0": (nerf_synthetic(0.0), "transforms.json", "camera_angle_x must be in (0, pi)"),
    "camera_angle_x pi": (nerf_synthetic(np.pi), "transforms.json", "camera_angle_x must be in (0, pi)"),
    "nan vertex, ascii ply": (write_mesh(NAN_TETRA, "ascii"), "mesh.ply", "NaN or Inf coordinates"),
    "nan vertex, binary ply": (write_mesh(NAN_TETRA, "binary"), "mesh.ply", "NaN or Inf coordinates"),
    "inf vertex, obj": (obj_mesh("v 0 0 0\nv inf 0 0\nv 0 1 0\nf 1 2 3\n"), "mesh.obj", "NaN or Inf"),
    "nan uv, obj": (obj_mesh("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt nan 0\nvt 0 1\nf 1/1 2/2 3/3\n"), "mesh.obj",
                    "UVs contain NaN"),
    "face index out of range": (ascii_ply_with_faces("3 0 1 7\n"), "mesh.ply", "outside 0..2"),
    # given UVs: dpi's textures cover the unit square, every face gets texels
    "tiled uvs, obj": (obj_mesh("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 3 0\nvt 0 1\nf 1/1 2/2 3/3\n"), "mesh.obj",
                       "1 of 3 mesh UVs lie outside [0, 1] (a tiled atlas)"),
    "negative uvs, obj": (obj_mesh("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt -0.5 0\nvt 1 0\nvt -0.5 1\nf 1/1 2/2 3/3\n"),
                          "mesh.obj", "2 of 3 mesh UVs lie outside [0, 1]"),
    "uvs at one point, obj": (obj_mesh("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0.5 0.5\nvt 0.5 0.5\nvt 0.5 0.5\n"
                                       "f 1/1 2/2 3/3\n"), "mesh.obj", "the mesh UVs have no area"),
    "uvs on a line, obj": (obj_mesh("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 0.5 0.5\nvt 1 1\nf 1/1 2/2 3/3\n"),
                           "mesh.obj", "the mesh UVs have no area"),
    "half the surface unmapped, obj": (obj_mesh("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 0 1\n"
                                                "vt 0.2 0.2\nf 1/1 2/2 3/3\nf 2/4 4/4 3/4\n"), "mesh.obj",
                                       "50% of the surface's area lies on faces without area in the UV atlas"),
    "gt mesh with tiled uvs": (lambda r: tiled_true_surface(r / "gt" / "mesh.ply"), "mesh.ply", "lie outside [0, 1]"),
    "all-black png": (fill_png("r_0", 0), "r_0.png", "all black"),
    "all-black exr": (lambda r: raw_exr(r / "images" / "r_2.exr", np.zeros((SIZE, SIZE, 3))), "r_2.exr", "all black"),
    "all-saturated png": (fill_png("r_1", 255), "r_1.png", "every pixel is clipped"),
    "constant exr": (lambda r: raw_exr(r / "images" / "r_3.exr", np.full((SIZE, SIZE, 3), 7.0)), "r_3.exr",
                     "every pixel is clipped at 7"),
    "scene.yaml not UTF-8": (lambda r: (r / "scene.yaml").write_bytes(b"prior: \xff\xfe\n"), "scene.yaml", "UTF-8"),
    # values of the wrong type: the frame, the key, the value and the type expected
    "focal true": (set_frame("fl_x", True), "transforms.json",
                   "frame 0 (images/r_0.png): fl_x must be a number, got true (a boolean)"),
    "focal null": (set_frame("fl_x", None), "transforms.json", "frame 0 (images/r_0.png): fl_x must be a number, got null"),
    "focal fifty": (set_frame("fl_x", "fifty"), "transforms.json", 'fl_x must be a number, got "fifty" (a string)'),
    "held_out string": (set_frame("held_out", "false", 1), "transforms.json",
                        'frame 1 (./images/r_1): held_out must be a boolean (true or false), got "false" (a string)'),
    "held_out number": (set_frame("held_out", 1, 2), "transforms.json",
                        "frame 2 (r_2): held_out must be a boolean (true or false), got 1 (a number)"),
    "width fractional": (set_frame("w", 8.5), "transforms.json", "w must be an integer, got 8.5 (a number)"),
    "width with unit": (set_frame("h", "8px"), "transforms.json", 'h must be an integer, got "8px" (a string)'),
    "matrix entry string": (set_matrix_entry("1.5"), "transforms.json",
                            'frame 0 (images/r_0.png): transform_matrix[0][3] must be a number, got "1.5" (a string)'),
    "matrix entry boolean": (set_matrix_entry(False), "transforms.json",
                             "transform_matrix[0][3] must be a number, got false (a boolean)"),
    "file_path number": (set_frame("file_path", 3), "transforms.json", "frame 0: file_path must be a string, got 3"),
    # images too small, depth-only EXRs
    "1x1 image": (lambda r: write_cv2(r / "images" / "r_0.png", np.full((1, 1, 3), 90, np.uint8)), "r_0.png",
                  "image is 1x1 px; dpi needs at least 8 px on each side"),
    "7 px high image": (lambda r: write_cv2(r / "images" / "r_1.png", np.full((7, 12, 3), 90, np.uint8)), "r_1.png",
                        "image is 12x7 px"),
    "depth-only exr image": (exr_channels("images/r_2.exr", "Z"), "r_2.exr",
                             "EXR channels Z hold no image: dpi reads R, G, B (with or without A) or Y (grey)"),
    "two-channel exr image": (exr_channels("images/r_3.exr", "UV"), "r_3.exr", "EXR channels U, V hold no image"),
    # ground truth, checked up front as the evaluation reads it
    "negative gt envmap": (gt_values("envmap", (4, 8, 3), -1.0), "envmap.exr",
                           "environment map has NaN, Inf or negative values"),
    "overflowing gt envmap": (gt_values("envmap", (4, 8, 3), 1e38), "envmap.exr",
                              "sums over its 96 values overflow 32-bit floats"),
    "nan gt albedo": (gt_values("albedo", (16, 16, 3), np.nan), "albedo.exr",
                      "ground truth albedo has NaN, Inf or negative values"),
    "negative gt roughness": (gt_values("roughness", (16, 16, 3), -0.5), "roughness.exr",
                              "ground truth roughness has NaN, Inf or negative values"),
    "gt envmap taller than wide": (gt_values("envmap", (8, 4, 3), 1.0), "envmap.exr", "8x4 is not an equirectangular map"),
    "depth-only gt envmap": (exr_channels("gt/envmap.exr", "Z"), "envmap.exr", "EXR channels Z hold no image"),
    "gt albedo not square": (gt_values("albedo", (16, 12, 3), 0.5), "albedo.exr", "is 12x16 px; a texture on the"),
    "gt textures of two sizes": (gt_values("roughness", (8, 8, 3), 0.5), "roughness.exr", "share one atlas"),
    # the true surface, read through the capture's validation
    "gt mesh a link outside": (lambda r: link_outside(r / "gt" / "mesh.ply"), "mesh.ply", "lies outside the capture"),
    "gt mesh a text file": (lambda r: (r / "gt" / "mesh.ply").write_text(SECRET), "mesh.ply", "unreadable mesh"),
    "gt mesh without faces": (lambda r: trimesh.PointCloud(np.eye(3)).export(r / "gt" / "mesh.ply"), "mesh.ply",
                              "mesh has no faces"),
    "gt mesh without uvs": (lambda r: trimesh.creation.box().export(r / "gt" / "mesh.ply"), "mesh.ply", "has no UVs"),
    "gt mesh with nan vertices": (lambda r: nan_mesh(r / "gt" / "mesh.ply"), "mesh.ply", "NaN or Inf coordinates"),
}

SECRET = "root:x:0:0:root:/root:/bin/bash\n"
"""a system file's first line: no message may quote it"""


def link_outside(path: Path) -> None:
    """`path` made a link to a text file beside the capture folder (outside it)."""
    outside = path.parents[2] / "passwd"
    outside.write_text(SECRET)
    path.symlink_to(outside)


def tiled_true_surface(path: Path) -> None:
    """A true surface whose UVs repeat the texture twice."""
    mesh = trimesh.creation.box()
    mesh.visual = trimesh.visual.TextureVisuals(uv=np.tile([[0.0, 0.0], [2.0, 2.0]], (4, 1)))
    mesh.export(path)


def nan_mesh(path: Path) -> None:
    mesh = trimesh.creation.box()
    mesh.vertices[0, 0] = np.nan
    mesh.export(path)


@pytest.mark.parametrize("case", list(BROKEN))
def test_broken_capture_stops_with_one_error_naming_the_file(tmp_path, case):
    """load_capture raises one single-line CaptureError that starts with the file; capture.json is not written."""
    break_capture, file_name, words = BROKEN[case]
    root = make_capture(tmp_path / "scene")
    break_capture(root)
    out = tmp_path / "results" / "capture.json"
    with pytest.raises(CaptureError) as info:
        normalise_capture(root, out)
    message = str(info.value)
    assert message.split(":")[0].endswith(file_name) and words in message and "\n" not in message, message
    assert "root:x" not in message
    assert not out.parent.exists()


def test_nearly_orthonormal_cameras_pass(tmp_path, mi):
    """Rounding noise of 1e-5 in a pose (printed with few digits) is not an error, and Mitsuba accepts it."""
    root = make_capture(tmp_path / "scene")
    set_rotation(noisy)(root)
    assert to_mitsuba(load_capture(root).views[0].camera)["fov"] == pytest.approx(40.0, rel=1e-3)


def noisy(c2w: np.ndarray) -> np.ndarray:
    """The rotation with 1e-5 of seeded noise on every entry."""
    c2w[:3, :3] += 1e-5 * np.random.default_rng(0).standard_normal((3, 3))
    return c2w


def test_partly_clipped_png_warns_with_the_clipped_fraction(tmp_path):
    """A quarter of the pixels at white: usable, with a warning that says 25.0%."""
    root = make_capture(tmp_path / "scene")
    codes = np.full((SIZE, SIZE, 3), 100, np.uint8)
    codes[:2, :, 1] = 255  # one channel at white clips the pixel
    write_cv2(root / "images" / "r_0.png", codes)
    with pytest.warns(CaptureWarning, match=r"r_0\.png: 25\.0% of the pixels are clipped at white"):
        load_capture(root)


def test_a_cut_outs_white_transparent_background_does_not_count_as_clipped(tmp_path):
    """An RGBA cut-out whose transparent half is white: the clipped share counts the opaque pixels only (none)."""
    root = make_capture(tmp_path / "scene")
    rgba = np.full((SIZE, SIZE, 4), 100, np.uint8)
    rgba[: SIZE // 2, :, :3], rgba[: SIZE // 2, :, 3], rgba[SIZE // 2:, :, 3] = 255, 0, 255
    write_cv2(root / "images" / "r_0.png", rgba)
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message=".*clipped at white", category=CaptureWarning)
        check_signal(root / "images" / "r_0.png", read_image(root / "images" / "r_0.png"))


def test_a_few_white_pixels_do_not_warn(tmp_path):
    """Below 1% of white pixels (a specular glint) passes silently."""
    (tmp_path / "images").mkdir()
    codes = np.full((128, 128, 3), 100, np.uint8)
    codes[0, :100] = 255
    for i, name in enumerate(NAMES):
        codes[64, 64] = 100 + i  # photos of one scene, not copies of one photo
        write_cv2(tmp_path / "images" / f"{name}.png", codes)
    (tmp_path / "scene.yaml").write_text("held_out: [r_3]\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error", CaptureWarning)
        assert load_capture(tmp_path).image_size == (128, 128)


def test_black_foreground_everywhere_names_the_capture():
    """Images black under every mask leave no exposure to normalise by: an error naming the capture."""
    import torch

    images = [torch.zeros(4, 4, 3), torch.ones(4, 4, 3)]
    masks = [torch.ones(4, 4, dtype=torch.bool), torch.zeros(4, 4, dtype=torch.bool)]
    with pytest.raises(ValueError, match=r"^captures/x: every foreground pixel of the training views is black"):
        capture_exposure(images, masks, "captures/x")


# --- scene.yaml, read before the workflow builds its DAG --------------------------------------


SCENE_YAML = {
    "invalid yaml": ("prior: [indoor\n", "invalid YAML (expected ',' or ']'"),
    "unknown prior family": ("prior: martian\n", "prior must be one of indoor, outdoor, got 'martian'"),
    "not a mapping": ("- indoor\n", "not a mapping"),
    "unknown key": ("prior: indoor\npriors: outdoor\n", "unknown keys: priors"),
    "bad held_out": ("held_out: r_0\n", "held_out must be a list"),
    "zero focal": ("focal_length_px: 0\n", "focal_length_px must be a positive number"),
    "held_out boolean": ("held_out: [r_0, true]\n", "held_out[1] must be an image name (a string), got true (a boolean)"),
    "radiance_scale string": ('radiance_scale: "2"\n', 'radiance_scale must be a positive number, got "2" (a string)'),
    "focal boolean": ("focal_length_px: yes\n", "focal_length_px must be a positive number (pixels), got true (a boolean)"),
}


@pytest.mark.parametrize("case", list(SCENE_YAML))
def test_bad_scene_yaml_is_named_by_the_parse_time_inspection(tmp_path, case):
    """What rules/common.smk calls for every scene before the DAG (inspect_capture, read_scene_options) stops
    on a bad scene.yaml with one line naming it."""
    text, words = SCENE_YAML[case]
    root = make_capture(tmp_path / "scene")
    (root / "scene.yaml").write_text(text)
    for check in (inspect_capture, read_scene_options):
        with pytest.raises(CaptureError) as info:
            check(root)
        message = str(info.value)
        assert message.startswith(f"{root / 'scene.yaml'}: ") and words in message and "\n" not in message, message


def test_valid_capture_json_is_written_when_nothing_is_wrong(tmp_path):
    """The control case of the table above: the same builder gives a capture that validates."""
    root = make_capture(tmp_path / "scene")
    normalise_capture(root, tmp_path / "capture.json")
    assert len(json.loads((tmp_path / "capture.json").read_text())["views"]) == len(NAMES)


def photos_only(root: Path, count: int, same: tuple[int, ...] = (), exr: bool = False) -> Path:
    """A capture of `count` photos and nothing else; the photos at the indices `same` are copies of the first."""
    (root / "images").mkdir(parents=True)
    rng = np.random.default_rng(3)
    first = None
    for i in range(count):
        codes = rng.integers(20, 230, (24, 24, 3), dtype=np.uint8)
        first = codes if first is None else first
        codes = first if i in same else codes
        if exr:
            raw_exr(root / "images" / f"p_{i}.exr", srgb_to_linear(codes / 255.0))
        else:
            write_cv2(root / "images" / f"p_{i}.png", codes)
    return root


@pytest.mark.parametrize("count, same, exr, words", [
    (1, (), False, "1 photo(s) and no cameras"),
    (2, (), False, "2 photo(s) and no cameras"),
    (2, (), True, "2 photo(s) and no cameras"),
    (5, (3,), False, "p_3.png: the same photo as p_0.png (identical pixels)"),
    (6, (1, 4), True, "p_1.exr: the same photo as p_0.exr (identical pixels)"),
])
def test_photos_that_cannot_give_cameras_are_refused_up_front(tmp_path, count, same, exr, words):
    root = photos_only(tmp_path / "scene", count, same, exr)
    with pytest.raises(CaptureError, match=re.escape(words)) as info:
        load_capture(root)
    assert "\n" not in str(info.value)


def test_identical_photos_with_given_cameras_are_not_refused(tmp_path):
    """Copies are refused only where the cameras must come from the photos."""
    root = make_capture(tmp_path / "scene")
    shutil.copyfile(root / "images" / "r_0.png", root / "images" / "r_1.png")
    load_capture(root)
