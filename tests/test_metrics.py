"""Metric known answers: identical images, a known shift, scaled maps and albedos."""

import numpy as np
import pytest

from dpi.metrics import albedo_mse, env_metrics, psnr, sample_variance, ssim


def test_psnr_known_answers():
    a = np.full((8, 8, 3), 0.5)
    assert psnr(a, a) == float("inf")
    assert psnr(a, a + 0.1) == pytest.approx(20.0)
    mask = np.zeros((8, 8), bool)
    mask[:2] = True
    b = a.copy()
    b[2:] = 0  # differences only outside the mask
    assert psnr(a, b, mask) == float("inf")


def test_ssim_identical_is_one():
    a = np.random.default_rng(0).random((16, 32, 3))
    assert ssim(a, a) == pytest.approx(1.0)
    assert ssim(a, 1 - a) < 0.5


def test_env_metrics_ignore_a_global_scale():
    env = np.random.default_rng(1).random((8, 16, 3)).astype(np.float32) * 5
    m = env_metrics(3.0 * env, env)
    assert m["env_scale"] == pytest.approx(1 / 3, rel=1e-4)
    assert m["env_psnr"] > 60 and m["env_ssim"] == pytest.approx(1.0, abs=1e-4)


def test_env_metrics_resize_the_reference():
    env = np.ones((16, 32, 3), np.float32)
    assert env_metrics(np.ones((8, 16, 3), np.float32), env)["env_psnr"] == float("inf")


def test_albedo_mse_aligns_each_channel():
    albedo = np.random.default_rng(2).random((8, 8, 3))
    mse, scales = albedo_mse(albedo * np.array([0.5, 2.0, 1.0]), albedo)
    assert mse == pytest.approx(0.0, abs=1e-20)
    np.testing.assert_allclose(scales, [2.0, 0.5, 1.0])


def test_sample_variance_known_answer():
    assert sample_variance([np.zeros(4), np.full(4, 2.0)]) == pytest.approx(2.0)
    assert sample_variance([np.ones(3)]) == 0.0
