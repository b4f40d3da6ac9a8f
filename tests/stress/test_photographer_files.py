"""What photographers' folders bring (issue: real photos): EXIF orientation, OS clutter, Unicode-normalised names,
nerfstudio's per-frame mask_path. Each is read correctly, or named in one line."""

import unicodedata
from pathlib import Path

import numpy as np
import pytest
from capture_helpers import NAMES, SIZE, edit_transforms, make_capture, sphere_mask
from PIL import Image, ImageOps

from dpi.capture import CaptureError, inspect_capture, load_capture
from dpi.io.images import decode_ldr, read_mask, write_mask
from dpi.preprocess.sfm import upright_copies


def tagged(path: Path, pixels: np.ndarray, orientation: int) -> Path:
    """A JPEG/PNG of `pixels` (stored as they are) with an EXIF orientation tag."""
    image = Image.fromarray(pixels)
    exif = image.getexif()
    exif[0x0112] = orientation
    image.save(path, exif=exif)
    return path


@pytest.mark.parametrize("orientation", range(1, 9))
def test_exif_orientation_turns_a_photo_as_pillow_does(tmp_path, orientation):
    pixels = (np.random.default_rng(orientation).random((5, 7, 3)) * 255).astype(np.uint8)
    path = tagged(tmp_path / "photo.png", pixels, orientation)
    with Image.open(path) as image:
        expected = np.asarray(ImageOps.exif_transpose(image).convert("RGB"), np.float32) / 255
    assert np.array_equal(decode_ldr(path), expected)


def test_a_sideways_photo_and_its_upright_mask_agree(tmp_path):
    """A photo stored sideways with orientation 6 (a phone held upright) is read upright, like its mask; COLMAP
    gets upright copies of it."""
    root = make_capture(tmp_path / "cap")
    upright = np.zeros((SIZE, SIZE, 3), np.uint8)
    upright[:, : SIZE // 2] = 200  # left half bright: not symmetric under a quarter turn
    stored = np.rot90(upright, 1)  # what the camera stored; orientation 6 turns it back clockwise
    (root / "images" / "r_0.png").unlink()
    tagged(root / "images" / "r_0.png", np.ascontiguousarray(stored), 6)
    assert np.array_equal(decode_ldr(root / "images" / "r_0.png")[..., 0] > 0.5, upright[..., 0] > 100)
    load_capture(root)
    copy = upright_copies([root / "images" / "r_0.png"], tmp_path / "upright")[0]
    with Image.open(copy) as image:
        assert image.size == (SIZE, SIZE) and np.array_equal(np.asarray(image)[..., 0] > 100, upright[..., 0] > 100)


def test_os_clutter_in_images_is_skipped(tmp_path):
    root = make_capture(tmp_path / "cap")
    for name in ("Thumbs.db", "desktop.ini", ".DS_Store"):
        (root / "images" / name).write_bytes(b"\x00clutter")
        (root / "masks" / name).write_bytes(b"\x00clutter")
    assert [v.name for v in load_capture(root).views] == list(NAMES)


def test_names_match_across_unicode_normal_forms(tmp_path):
    """A file name written decomposed (macOS) matches transforms.json's composed one."""
    root = make_capture(tmp_path / "cap")
    composed = unicodedata.normalize("NFC", "vue_é")
    (root / "images" / "r_0.png").rename(root / "images" / (unicodedata.normalize("NFD", composed) + ".png"))
    (root / "masks" / "r_0.png").rename(root / "masks" / (unicodedata.normalize("NFD", composed) + ".png"))
    edit_transforms(root, lambda d: d["frames"][0].update(file_path=f"images/{composed}.png"))
    assert composed in [v.name for v in load_capture(root).views]


def test_per_frame_mask_path_is_read(tmp_path):
    """nerfstudio's `mask_path` per frame names the masks; no masks/ folder is needed."""
    root = make_capture(tmp_path / "cap", masks=False)
    mask = sphere_mask()
    for name in NAMES:
        write_mask(root / "segments" / f"{name}_mask.png", mask)
    edit_transforms(root, lambda d: [f.update(mask_path=f"segments/{n}_mask.png") for f, n in zip(d["frames"], NAMES)])
    assert inspect_capture(root)["masks"]
    capture = load_capture(root)
    assert capture.provenance["masks"] == "given"
    assert all(np.array_equal(read_mask(v.mask), mask) for v in capture.views)


def test_mask_path_on_some_frames_only_is_named(tmp_path):
    root = make_capture(tmp_path / "cap", masks=False)
    write_mask(root / "segments" / "a.png", sphere_mask())
    edit_transforms(root, lambda d: d["frames"][0].update(mask_path="segments/a.png"))
    with pytest.raises(CaptureError, match=r"transforms.json: 3 of 4 frames lack 'mask_path'"):
        load_capture(root)


def test_a_missing_mask_path_file_is_named(tmp_path):
    root = make_capture(tmp_path / "cap", masks=False)
    edit_transforms(root, lambda d: [f.update(mask_path=f"segments/{n}.png") for f, n in zip(d["frames"], NAMES)])
    with pytest.raises(CaptureError, match=r"segments/r_0.png: mask file does not exist"):
        load_capture(root)


def test_a_mask_saved_as_0_and_1_is_named_with_the_hint(tmp_path):
    root = make_capture(tmp_path / "cap")
    Image.fromarray(sphere_mask().astype(np.uint8)).save(root / "masks" / "r_1.png")  # 0/1, not 0/255
    with pytest.raises(CaptureError, match=r"r_1.png: empty mask .*largest value is 1 of 255: masks stored as 0/1"):
        load_capture(root)


def test_an_all_white_mask_is_named(tmp_path):
    root = make_capture(tmp_path / "cap")
    write_mask(root / "masks" / "r_2.png", np.ones((SIZE, SIZE), bool))
    with pytest.raises(CaptureError, match=r"r_2.png: mask is all foreground"):
        load_capture(root)


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_a_gltf_mesh_is_read_and_rendered_as_ply(tmp_path, suffix, mi):
    """A glTF mesh (nerfstudio and web exports) loads with its UVs and becomes a PLY that Mitsuba renders."""
    import trimesh

    from dpi.preprocess.derive import normalise_capture
    from dpi.render.renderer import RenderConfig, Renderer

    root = make_capture(tmp_path / "cap", mesh=False)
    sphere = trimesh.creation.icosphere(subdivisions=2)
    uv = np.stack([np.arctan2(sphere.vertices[:, 0], sphere.vertices[:, 2]) / (2 * np.pi) + 0.5,
                   sphere.vertices[:, 1] / 2 + 0.5], -1)
    sphere.visual = trimesh.visual.TextureVisuals(uv=uv)
    sphere.export(root / f"mesh{suffix}")
    capture = load_capture(root)
    assert capture.mesh.name == f"mesh{suffix}" and capture.mesh_has_uv
    normalise_capture(root, tmp_path / "results" / "capture.json")
    from dpi.capture import read_capture_json

    converted = read_capture_json(tmp_path / "results" / "capture.json")
    assert converted.mesh == tmp_path / "results" / "mesh_given.ply" and converted.mesh_has_uv
    back = trimesh.load(converted.mesh, process=False)
    assert np.allclose(back.vertices, sphere.vertices, atol=1e-6) and np.allclose(back.visual.uv, uv, atol=1e-6)
    cameras = [v.camera for v in converted.views][:1]
    renderer = Renderer(converted.mesh, cameras, 4, 8, RenderConfig(spp=4))
    import torch

    image = renderer.render(torch.ones(4, 8, 3), torch.full((8, 8, 3), 0.5), torch.full((8, 8, 1), 0.5),
                            torch.zeros(8, 8, 1), view=0, seed=0)
    assert image.shape == (SIZE, SIZE, 3) and float(image.mean()) > 0
