"""Relighting: the ground truth relit under its own map reproduces the capture, radiance is linear
in the map, material edits, rotation about the up axis, and bad inputs write nothing."""

import json

import numpy as np
import pytest
import torch

from dpi.capture import load_capture, write_capture_json
from dpi.cli import main
from dpi.export.relight import MaterialEdit, RelightConfig, relight_sample
from dpi.io.exr import EXRError, read_exr, write_exr
from dpi.io.images import linear_to_srgb, read_image
from dpi.light.envmap import direction_to_texel, rotate_azimuth, texel_directions
from dpi.render.renderer import RenderConfig
from dpi.solve.materials import MaterialTextures

RENDER = RenderConfig(spp=32, threads=2)


@pytest.fixture(scope="module")
def capture_json(tiny_capture, tmp_path_factory):
    path = tmp_path_factory.mktemp("relight") / "capture.json"
    write_capture_json(load_capture(tiny_capture), path)
    return path


def srgb_psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR in dB of two linear images after sRGB encoding."""
    mse = float(np.mean((linear_to_srgb(a).astype(np.float64) - linear_to_srgb(b)) ** 2))
    return 10 * np.log10(1 / mse)


def test_ground_truth_under_its_own_map_reproduces_the_capture(tiny_capture, capture_json, tmp_path):
    names = relight_sample(capture_json, tiny_capture / "gt", tmp_path / "own", RelightConfig(), RENDER)
    views = load_capture(tiny_capture).views
    assert names == [v.name for v in views]
    for view in views:
        assert srgb_psnr(read_exr(tmp_path / "own" / f"{view.name}.exr"), read_image(view.image)) > 30
        assert (tmp_path / "own" / f"{view.name}.png").is_file()
    # a turned environment no longer matches: the test above is not passing trivially
    relight_sample(capture_json, tiny_capture / "gt", tmp_path / "turned", RelightConfig(rotate_deg=180), RENDER)
    turned = read_exr(tmp_path / "turned" / f"{views[0].name}.exr")
    assert srgb_psnr(turned, read_image(views[0].image)) < 25
    assert json.loads((tmp_path / "turned" / "relight.json").read_text())["config"]["rotate_deg"] == 180


def test_twice_the_map_gives_twice_the_image(tiny_capture, capture_json, tmp_path):
    write_exr(tmp_path / "bright.exr", 2 * read_exr(tiny_capture / "gt" / "envmap.exr"))
    relight_sample(capture_json, tiny_capture / "gt", tmp_path / "one", RelightConfig(), RENDER)
    relight_sample(capture_json, tiny_capture / "gt", tmp_path / "two", RelightConfig(envmap=str(tmp_path / "bright.exr")),
                   RENDER)
    one, two = read_exr(tmp_path / "one" / "r_000.exr"), read_exr(tmp_path / "two" / "r_000.exr")
    np.testing.assert_allclose(two, 2 * one, rtol=1e-4, atol=1e-6)


def test_orbit_views_with_edited_materials(tiny_capture, capture_json, tmp_path):
    cfg = RelightConfig(orbit=3, env_height=4, edit=MaterialEdit(albedo_scale=(0.5, 0.5, 0.5), metallic=1.0))
    names = relight_sample(capture_json, tiny_capture / "gt", tmp_path / "orbit", cfg, RENDER)
    assert names == ["orbit_000", "orbit_001", "orbit_002"]
    for name in names:
        image = read_exr(tmp_path / "orbit" / f"{name}.exr")
        assert image.shape == (24, 24, 3) and np.isfinite(image).all()
    assert json.loads((tmp_path / "orbit" / "relight.json").read_text())["env_shape"] == [4, 8, 3]


def test_material_edit_known_answers():
    materials = MaterialTextures.constant(2, albedo=0.8, roughness=0.3, metallic=0.0)
    edited = MaterialEdit(albedo_scale=(0.5, 1.0, 2.0), roughness=0.7).apply(materials)
    torch.testing.assert_close(edited.albedo[0, 0], torch.tensor([0.4, 0.8, 1.0]))  # clipped to 1
    assert float(edited.roughness.min()) == pytest.approx(0.7) and float(edited.metallic.max()) == 0.0
    assert float(materials.roughness.max()) == pytest.approx(0.3)  # the input is untouched
    with pytest.raises(ValueError, match="metallic"):
        MaterialEdit(metallic=1.5)


def test_rotation_turns_the_map_about_the_up_axis():
    env = np.zeros((8, 16, 3), np.float32)
    direction = texel_directions(8)[2, 5]
    env[2, 5] = 1.0
    angle = np.radians(90.0)  # right-handed about +Y: x' = x cos + z sin, z' = -x sin + z cos
    turned = np.array([direction[0] * np.cos(angle) + direction[2] * np.sin(angle), direction[1],
                       -direction[0] * np.sin(angle) + direction[2] * np.cos(angle)])
    row, col = direction_to_texel(turned, 8)
    assert rotate_azimuth(env, 90.0)[row, col, 0] == 1.0
    np.testing.assert_allclose(rotate_azimuth(env, 360.0), env)
    half = rotate_azimuth(env, 360.0 / 32)  # half a texel: shared between two neighbours
    assert half[2, 4, 0] == pytest.approx(0.5) and half[2, 5, 0] == pytest.approx(0.5)


def test_bad_envmap_is_one_clear_error_and_writes_nothing(tiny_capture, capture_json, tmp_path, capsys):
    missing = tmp_path / "nope.exr"
    with pytest.raises(EXRError, match="nope.exr"):
        relight_sample(capture_json, tiny_capture / "gt", tmp_path / "out", RelightConfig(envmap=str(missing)), RENDER)
    broken = tmp_path / "broken.exr"
    broken.write_text("not an exr")
    code = main(["relight", str(capture_json), str(tiny_capture / "gt"), str(tmp_path / "out"),
                 "--envmap", str(broken), "--threads", "2"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "broken.exr" in err
    assert not (tmp_path / "out").exists()
