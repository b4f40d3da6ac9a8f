"""Env maps in the authors' layouts (a wrap column, a square equirect) are read as (H, 2H) wherever a
map is read: capture validation (gt), evaluation and relighting; other shapes stay clear errors."""

import shutil

import numpy as np
import pytest

from dpi.capture import CaptureError, load_capture, write_capture_json
from dpi.export.relight import RelightConfig, relight_sample
from dpi.io.exr import read_exr, write_exr
from dpi.light.envmap import EnvmapLayoutError, equirect, read_envmap
from dpi.render.renderer import RenderConfig


def smooth_map(height: int, width: int) -> np.ndarray:
    """A positive map whose columns vary smoothly and wrap (column `width` would equal column 0)."""
    phi = np.arange(width) / width * 2 * np.pi
    theta = (np.arange(height) + 0.5) / height * np.pi
    base = 1.0 + 0.5 * np.cos(phi)[None, :] * np.sin(theta)[:, None]
    return np.repeat(base[..., None], 3, axis=-1).astype(np.float32) * np.array([1.0, 0.8, 0.6], np.float32)


def with_wrap(env: np.ndarray) -> np.ndarray:
    return np.concatenate([env, env[:, :1]], axis=1)


def test_wrap_column_is_dropped_exactly():
    env = smooth_map(128, 256)
    out, notes = equirect(with_wrap(env), "sky.exr")
    np.testing.assert_array_equal(out, env)
    assert len(notes) == 1 and "sky.exr" in notes[0] and "wrap column" in notes[0] and "128x257" in notes[0]


def test_square_map_with_wrap_column_is_resampled_to_2_to_1():
    square = smooth_map(256, 256)
    out, notes = equirect(with_wrap(square), "gt/envmap.exr")
    assert out.shape == (256, 512, 3) and len(notes) == 2 and "resampled" in notes[1]
    # a horizontal stretch: every other column of the result is (close to) the square map's column
    np.testing.assert_allclose(out[:, ::2].mean(), square.mean(), rtol=1e-2)
    np.testing.assert_allclose(out.mean(axis=1), square.mean(axis=1), rtol=1e-2)


def test_a_2_to_1_map_is_left_alone():
    env = smooth_map(16, 32)
    out, notes = equirect(env)
    assert out is env and notes == []


@pytest.mark.parametrize("shape", [(16, 40), (16, 8), (16, 33 + 40)])
def test_other_shapes_are_one_clear_error(shape):
    with pytest.raises(EnvmapLayoutError, match=rf"bad.exr: {shape[0]}x{shape[1]} is not an equirectangular"):
        equirect(np.ones((*shape, 3), np.float32), "bad.exr")


def test_read_envmap_logs_each_change(tmp_path, capsys):
    write_exr(tmp_path / "sky.exr", with_wrap(smooth_map(8, 16)))
    env = read_envmap(tmp_path / "sky.exr")
    assert env.shape == (8, 16, 3) and "dropped the wrap column" in capsys.readouterr().out


@pytest.fixture()
def wrapped_capture(tiny_capture, tmp_path):
    """The tiny capture with its ground-truth map stored square with a wrap column (H x H+1)."""
    root = tmp_path / "wrapped"
    shutil.copytree(tiny_capture, root)
    env = read_exr(root / "gt" / "envmap.exr")
    h = env.shape[0]
    square = env.reshape(h, h, 2, 3).mean(axis=2)  # 2:1 -> 1:1 by averaging column pairs
    write_exr(root / "gt" / "envmap.exr", with_wrap(square))
    return root


def test_authors_layout_validates_evaluates_and_relights(wrapped_capture, tiny_capture, tmp_path):
    from dpi.evaluation.sample_metrics import env_truth_metrics
    from dpi.solve.decomposition import Decomposition

    capture = load_capture(wrapped_capture)  # validates: no error
    assert read_envmap(capture.gt["envmap"]).shape == read_exr(tiny_capture / "gt" / "envmap.exr").shape
    truth = Decomposition.load(tiny_capture / "gt")  # the original 2:1 map scored against the square copy
    metrics = env_truth_metrics(truth, capture.gt)
    assert metrics["env_psnr"] > 20  # the round trip loses only the azimuthal detail of the pair average
    write_capture_json(capture, tmp_path / "capture.json")
    names = relight_sample(tmp_path / "capture.json", wrapped_capture / "gt", tmp_path / "relit",
                           RelightConfig(envmap=str(wrapped_capture / "gt" / "envmap.exr")), RenderConfig(spp=4, threads=2))
    assert names and all((tmp_path / "relit" / f"{n}.exr").is_file() for n in names)


def test_a_gt_map_of_another_shape_fails_validation_naming_the_file(tiny_capture, tmp_path):
    root = tmp_path / "bad"
    shutil.copytree(tiny_capture, root)
    write_exr(root / "gt" / "envmap.exr", np.ones((8, 40, 3), np.float32))
    with pytest.raises(CaptureError, match=r"gt/envmap.exr: 8x40 is not an equirectangular"):
        load_capture(root)
