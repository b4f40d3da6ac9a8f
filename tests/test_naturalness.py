"""Naturalness under the diffusion prior: deterministic, scale-free, higher for a training-like map than for noise."""

import numpy as np
import pytest

from dpi.evaluation.naturalness import NaturalnessConfig, naturalness
from dpi.prior.sample import load_default_prior
from dpi.worlds.outdoor import outdoor_envmap

FAST = NaturalnessConfig(timesteps=(200, 500), seeds=(0,))


@pytest.fixture(scope="module")
def prior():
    return load_default_prior("outdoor")


def test_naturalness_is_deterministic_and_ignores_the_global_scale(prior):
    env = outdoor_envmap(32, np.random.default_rng(0))
    assert naturalness(env, prior, FAST) == naturalness(env, prior, FAST)
    assert naturalness(5 * env, prior, FAST) == pytest.approx(naturalness(env, prior, FAST), rel=1e-4)


def test_a_training_like_map_is_more_natural_than_noise(prior):
    rng = np.random.default_rng(1)
    sky = outdoor_envmap(32, rng)
    noise = np.exp(rng.normal(0, 2, sky.shape))
    # minus the denoising error: the prior denoises a map like its training maps far better than noise
    assert -naturalness(sky, prior, FAST) < 0.25 * -naturalness(noise, prior, FAST)
