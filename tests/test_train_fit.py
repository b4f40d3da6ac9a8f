"""The training-view fit of a decomposition: the truth fits better than a wrong map, and the two-render estimate
removes the re-render's own noise that a plain squared error adds."""

import numpy as np
import torch

from dpi.capture import load_capture
from dpi.evaluation.train_fit import training_fit
from dpi.evaluation.truth import true_decomposition
from dpi.render.renderer import RenderConfig
from dpi.solve.decomposition import Decomposition
from dpi.solve.problem import InverseProblem, ProblemConfig


def test_the_truth_fits_better_than_a_wrong_light_and_without_the_render_noise(tiny_capture):
    problem = InverseProblem(load_capture(tiny_capture), ProblemConfig(env_height=8, texture_size=16),
                             RenderConfig(spp=4, threads=2))
    truth = true_decomposition(problem)
    assert truth is not None
    fit = training_fit(problem, truth, spp=4, seed=0)
    wrong = Decomposition(truth.env.roll(8, dims=1) * 1.5, truth.materials)
    assert training_fit(problem, wrong, spp=4, seed=0) > 5 * abs(fit)
    with torch.no_grad():  # the plain squared error of one 4-spp render carries that render's variance
        plain = np.mean([float(problem.view_loss(problem.render(truth.env, truth.materials, v, v, 4), v))
                         for v in problem.train_ids])
    assert abs(fit) < 0.5 * plain
