"""Perceptual metrics: missing weights are reported, LPIPS and FID known answers, local weight loading."""

from pathlib import Path

import numpy as np
import pytest
import torch

from dpi.evaluation.perceptual import (ALEXNET_WEIGHTS, INCEPTION_WEIGHTS, WEIGHTS_ENV, azimuth_rolls, frechet_distance,
                                       import_torchvision, lpips_distance, lpips_network, missing_weights, weights_dir)
from dpi.evaluation.sample_metrics import lpips_network as evaluation_lpips


@pytest.fixture(scope="module")
def random_lpips():
    """LPIPS with its packaged linear layers and a randomly initialised AlexNet (nothing downloaded)."""
    torch.manual_seed(0)
    return lpips_network(None)


def test_missing_weights_name_the_file_and_folder(tmp_path, monkeypatch):
    monkeypatch.setenv(WEIGHTS_ENV, str(tmp_path))
    assert weights_dir() == tmp_path
    reason = missing_weights(INCEPTION_WEIGHTS)
    assert INCEPTION_WEIGHTS in reason and str(tmp_path) in reason
    value = evaluation_lpips()
    assert value.startswith("missing: ") and ALEXNET_WEIGHTS in value and str(tmp_path) in value
    (tmp_path / ALEXNET_WEIGHTS).touch()
    assert missing_weights(ALEXNET_WEIGHTS) is None


def test_default_weights_dir_is_torch_hub(monkeypatch):
    monkeypatch.delenv(WEIGHTS_ENV, raising=False)
    assert weights_dir() == Path(torch.hub.get_dir()) / "checkpoints"


def test_lpips_identical_is_zero_and_different_positive(random_lpips):
    rng = np.random.default_rng(0)
    a = rng.random((16, 32, 3)).astype(np.float32)  # upsampled to 64 px: AlexNet needs more than 32
    assert lpips_distance(a, a, random_lpips) == pytest.approx(0.0, abs=1e-7)
    assert lpips_distance(a, 1 - a, random_lpips) > 0


def test_lpips_backbone_loads_from_a_torchvision_checkpoint(tmp_path):
    alexnet = import_torchvision().models.alexnet(weights=None)
    torch.save({f"features.{k}": v for k, v in alexnet.features.state_dict().items()}, tmp_path / ALEXNET_WEIGHTS)
    net = lpips_network(tmp_path / ALEXNET_WEIGHTS)
    torch.testing.assert_close(net.net.slice2[1].weight, alexnet.features[3].weight)  # conv2 is features[3]


def test_frechet_distance_known_answers():
    rng = np.random.default_rng(1)
    f = rng.normal(size=(30, 5))
    shift = np.array([1.0, -2.0, 0.5, 0.0, 3.0])
    assert frechet_distance(f, f) == pytest.approx(0.0, abs=1e-9)
    assert frechet_distance(f, f + shift) == pytest.approx(shift @ shift)
    # same mean, covariances S and 4 S: d = tr S + tr 4S - 2 tr (4 S^2)^1/2 = tr S
    g = rng.normal(size=(40, 3))
    assert frechet_distance(g, 2 * (g - g.mean(0)) + g.mean(0)) == pytest.approx(np.trace(np.cov(g, rowvar=False)))


def test_frechet_distance_matches_pytorch_fid():
    import_torchvision()
    from pytorch_fid.fid_score import calculate_frechet_distance

    rng = np.random.default_rng(2)
    a, b = rng.normal(size=(40, 8)), 1.5 * rng.normal(size=(50, 8)) + 0.3
    expected = calculate_frechet_distance(a.mean(0), np.cov(a, rowvar=False), b.mean(0), np.cov(b, rowvar=False))
    assert frechet_distance(a, b) == pytest.approx(expected, rel=1e-8)


def test_azimuth_rolls_rotate_about_the_up_axis():
    env = np.arange(8 * 2 * 3, dtype=float).reshape(2, 8, 3)
    rolls = azimuth_rolls(env, 4)
    assert len(rolls) == 4 and np.array_equal(rolls[0], env)
    assert np.array_equal(rolls[1][:, 2:], env[:, :-2])
