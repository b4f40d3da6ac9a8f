"""The readings' evidence: the misfit without the renders' noise, and the paired comparison's known answers."""

import math

import pytest
import torch

from dpi.capture import load_capture
from dpi.render.renderer import RenderConfig
from dpi.solve.evidence import normal_cdf, paired_difference, reading_evidence
from dpi.solve.materials import MaterialTextures
from dpi.solve.problem import InverseProblem, ProblemConfig


def test_the_paired_difference_has_the_mean_and_standard_error_of_independent_pixels():
    generator = torch.Generator().manual_seed(0)
    masks = [torch.rand(32, 32, generator=generator) < 0.7 for _ in range(6)]
    mean, error, blocks = paired_difference([0.3 + 2.0 * torch.randn(32, 32, generator=generator) for _ in masks],
                                            masks)
    pixels = sum(int(m.sum()) for m in masks)
    assert blocks == 6 * 64
    assert mean == pytest.approx(0.3, abs=4 * 2.0 / math.sqrt(pixels))
    assert error == pytest.approx(2.0 / math.sqrt(pixels), rel=0.15)


def test_normal_cdf_known_values():
    assert normal_cdf(0.0) == 0.5
    assert normal_cdf(1.959964) == pytest.approx(0.975, abs=1e-6)
    assert normal_cdf(-1.959964) == pytest.approx(0.025, abs=1e-6)


@pytest.fixture(scope="module")
def problems(tiny_capture):
    capture = load_capture(tiny_capture)
    return {spp: InverseProblem(capture, ProblemConfig(env_height=8, texture_size=8), RenderConfig(spp=spp, threads=2))
            for spp in (4, 32)}


@pytest.fixture(scope="module")
def truth(problems):
    from dpi.evaluation.truth import true_decomposition

    return true_decomposition(problems[4])


def test_the_misfit_does_not_change_with_the_renders_noise(problems, truth):
    wrong = MaterialTextures.constant(8, 0.5, 0.5, 0.0)
    fits = {"rough": (truth.env, truth.materials), "glossy": (truth.env * 0.5, wrong)}
    low, high = (reading_evidence(problems[spp], fits, seed=3) for spp in (4, 32))
    for name in fits:
        assert low[name]["noise"] == pytest.approx(8 * high[name]["noise"], rel=0.35)  # Monte Carlo variance ~ 1/spp
        assert low[name]["misfit"] == pytest.approx(high[name]["misfit"], abs=0.5 * high["rough"]["noise"] * 8)
    assert high["glossy"]["misfit"] > 3 * high["rough"]["misfit"]


def test_the_reading_that_explains_the_views_is_the_likely_one(problems, truth):
    wrong = (truth.env * 0.5, MaterialTextures.constant(8, 0.5, 0.5, 0.0))
    right = (truth.env, truth.materials)
    problem = problems[4]
    assert reading_evidence(problem, {"rough": wrong, "glossy": right}, seed=3)["p_glossy"] > 0.999
    assert reading_evidence(problem, {"rough": right, "glossy": wrong}, seed=3)["p_glossy"] < 0.001
    same = reading_evidence(problem, {"rough": right, "glossy": right}, seed=3)
    assert same["z"] == 0.0 and same["p_glossy"] == 0.5
