"""NIQE: agreement with scikit-video's reference, noise scores worse, determinism, size limits."""

import numpy as np
import pytest
from skimage import data

from dpi.evaluation.niqe import env_niqe, niqe, pristine_model
from dpi.worlds.outdoor import outdoor_envmap


def test_pristine_model_is_a_covariance():
    mu, cov = pristine_model()
    assert mu.shape == (36,) and cov.shape == (36, 36)
    np.testing.assert_allclose(cov, cov.T)
    assert np.linalg.eigvalsh(cov).min() > -1e-9


def test_niqe_matches_scikit_video_and_penalises_noise():
    camera = data.camera().astype(np.float64)
    assert niqe(camera) == pytest.approx(9.0707, rel=2e-3)  # scikit-video 1.1.11's niqe on the same image
    noisy = np.clip(camera + np.random.default_rng(0).normal(0, 25, camera.shape), 0, 255)
    assert niqe(noisy) > niqe(camera) + 5


def test_env_niqe_is_deterministic_and_penalises_noise():
    env = outdoor_envmap(32, np.random.default_rng(0))
    noisy = env * np.exp(np.random.default_rng(1).normal(0, 1, env.shape))
    assert env_niqe(env) == env_niqe(env)
    assert env_niqe(noisy) > env_niqe(env) + 5


def test_niqe_needs_one_patch():
    with pytest.raises(ValueError, match="96x96"):
        niqe(np.zeros((64, 200)))
