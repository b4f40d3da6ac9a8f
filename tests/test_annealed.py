"""The annealed sampler's parts on known answers: the posterior variance of a Gaussian prior, the grid's
Laplacian, conjugate gradients, the resampling matrices, and a conditional draw that recovers the map an
exact linear operator determines."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from dpi.materials import MaterialTextures
from dpi.solve.decomposition import Decomposition
from dpi.solve.dps import DPSConfig, start_run
from dpi.solve.dps.annealed import (Resampling, conditional_draw, conjugate_gradients, negative_laplacian,
                                    posterior_variance)
from dpi.solve.prior_space import resample_env
from dpi.solve.transport import Transport
from test_samplers import LinearProblem, gaussian_prior


def test_posterior_variance_of_a_gaussian_prior():
    # x_t = sqrt(abar) x0 + sqrt(1 - abar) eps with x0 ~ N(0, s^2): Var(x0 | x_t) = 1 / (1/s^2 + abar / (1 - abar))
    for abar, s in ((0.3, 0.5), (0.9, 1.0), (1e-4, 0.5)):
        assert posterior_variance(abar, s) == pytest.approx(1 / (1 / s**2 + abar / (1 - abar)))


def test_laplacian_quadratic_form_sums_squared_neighbour_differences():
    x = torch.randn(1, 4, 8, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    azimuth = (x - torch.roll(x, 1, dims=2)).square().sum()
    polar = (x[:, 1:] - x[:, :-1]).square().sum()
    assert float((x * negative_laplacian(x)).sum()) == pytest.approx(float(azimuth + polar))


def test_conjugate_gradients_solve_a_batch_of_spd_systems():
    g = torch.Generator().manual_seed(1)
    a = torch.randn(3, 20, 20, generator=g, dtype=torch.float64)
    matrix = a @ a.transpose(1, 2) + 0.5 * torch.eye(20, dtype=torch.float64)
    truth = torch.randn(3, 20, generator=g, dtype=torch.float64)
    rhs = torch.einsum("cij,cj->ci", matrix, truth)
    x = conjugate_gradients(lambda v: torch.einsum("cij,cj->ci", matrix, v), rhs,
                            matrix.diagonal(dim1=1, dim2=2), iterations=200, tolerance=1e-12)
    torch.testing.assert_close(x, truth)


@pytest.mark.parametrize("prior_height,env_height", [(8, 4), (8, 8), (4, 8)])
def test_resampling_matrices_are_resample_env(prior_height, env_height):
    x = torch.rand(1, 3, prior_height, 2 * prior_height, dtype=torch.float64)
    r = Resampling.between(prior_height, env_height)
    expected = resample_env(x, env_height).reshape(-1, 3).T
    torch.testing.assert_close(r.apply(x.reshape(3, -1)), expected)
    y = torch.rand(3, 2 * env_height**2, dtype=torch.float64)
    torch.testing.assert_close((r.transpose(y) * x.reshape(3, -1)).sum(), (y * expected).sum())  # the adjoint


def exact_transport(truth: torch.Tensor, pixels: int, seed: int) -> Transport:
    """The normal equations of a random exact operator per channel that sees every texel: y_c = T_c L_c."""
    g = torch.Generator().manual_seed(seed)
    texels = truth.shape[0] * truth.shape[1]
    operators = torch.rand(3, pixels, texels, generator=g, dtype=torch.float64) / texels
    y = torch.einsum("cpn,nc->cp", operators, truth.reshape(-1, 3).double())
    return Transport(operators.transpose(1, 2) @ operators, torch.einsum("cpn,cp->cn", operators, y),
                     float(y.square().sum()), pixels, truth.shape[0], [0], MaterialTextures.constant(4), 0.0, 0,
                     torch.zeros(3, texels, dtype=torch.float64))


def test_a_draw_with_a_weak_prior_recovers_what_the_views_determine():
    """With a negligible prior and no noise the draw is the map an exact operator determines (the exposure
    the draw solves for included)."""
    height = 4
    truth = torch.exp(torch.randn(height, 2 * height, 3, generator=torch.Generator().manual_seed(2)))
    init = Decomposition(torch.ones(height, 2 * height, 3), MaterialTextures.constant(4))
    cfg = DPSConfig.from_dict({"sampler": "annealed", "steps": 10, "radiance_scale": 1.0,
                               "annealed": {"solver_iterations": 30, "smoothness": 0.0}})
    run, state = start_run(LinearProblem(truth), gaussian_prior(height), init, cfg, seed=0)
    conditional_draw(run, state, exact_transport(truth, 200, 3), torch.zeros(1, 3, height, 2 * height),
                     variance=1e6, sigma2=1e-12)
    found = run.env(torch.exp(state.log_map), state).detach()
    np.testing.assert_allclose(found.numpy(), truth.numpy(), rtol=2e-2)
