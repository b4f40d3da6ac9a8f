"""Env-map figure: a readable PNG grid with one row per method plus the ground truth."""

import numpy as np
from PIL import Image

from dpi.evaluation.figures import display_env, envmap_grid
from dpi.io.exr import write_exr


def test_display_aligns_scale_to_the_reference():
    env = np.random.default_rng(0).random((4, 8, 3)).astype(np.float32)
    np.testing.assert_allclose(display_env(10 * env, env), display_env(env, env), atol=1e-5)
    assert 0 <= display_env(env, None).min() and display_env(env, None).max() < 1


def test_grid_has_a_row_per_method_and_the_ground_truth(tmp_path):
    paths = []
    for i in range(3):
        paths.append(tmp_path / f"e{i}.exr")
        write_exr(paths[-1], np.full((4, 8, 3), i + 1.0, np.float32))
    one = tmp_path / "one.png"
    envmap_grid([("a", paths[:1])], one)
    three = tmp_path / "three.png"
    envmap_grid([("a", paths[:2]), ("b", paths[2:])], three, reference=paths[0])
    h1, h3 = Image.open(one).height, Image.open(three).height
    assert h3 > 2.5 * h1 and Image.open(three).width > Image.open(one).width


def test_ground_truth_in_the_authors_layout_is_drawn_as_the_samples_are(tmp_path, monkeypatch):
    """A 256 x 257 ground truth (square-ish, with a wrap column) is drawn H x 2H through the one map reader,
    next to 16 x 32 samples, not square as stored."""
    import dpi.evaluation.figures as figures

    drawn = []
    monkeypatch.setattr(figures, "save_figure", lambda fig, path: drawn.extend(
        im.get_array().shape[:2] for ax in fig.axes for im in ax.get_images()))
    gt = np.random.default_rng(1).uniform(0.5, 2.0, (256, 256, 3)).astype(np.float32)
    write_exr(tmp_path / "gt.exr", np.concatenate([gt, gt[:, :1]], axis=1))
    write_exr(tmp_path / "s.exr", np.ones((16, 32, 3), np.float32))
    envmap_grid([("dps", [tmp_path / "s.exr"])], tmp_path / "grid.png", reference=tmp_path / "gt.exr")
    assert drawn == [(256, 512), (16, 32)]  # was (256, 257): the stored array
