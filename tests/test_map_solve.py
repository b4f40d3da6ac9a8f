"""The map solve's parts on known answers: the posterior variance of a Gaussian prior, conjugate gradients on a
batch of systems, and the resampling matrices (resample_env and its adjoint)."""

from __future__ import annotations

import pytest
import torch

from dpi.solve.dps.map_solve import Resampling, conjugate_gradients, posterior_variance
from dpi.solve.prior_space import resample_env


def test_posterior_variance_of_a_gaussian_prior():
    # x_t = sqrt(abar) x0 + sqrt(1 - abar) eps with x0 ~ N(0, s^2): Var(x0 | x_t) = 1 / (1/s^2 + abar / (1 - abar))
    for abar, s in ((0.3, 0.5), (0.9, 1.0), (1e-4, 0.5)):
        assert posterior_variance(abar, s) == pytest.approx(1 / (1 / s**2 + abar / (1 - abar)))


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
