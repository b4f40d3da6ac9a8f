"""The gibbs sampler's parts on known answers: the posterior variance of a Gaussian prior, the grid Laplacian and
draws of its Gaussian field, conjugate gradients, the resampling matrices, draws of the map and the albedo that
recover what exact views determine and keep the prior's spread where there are none, and the roughness level
that generated the views."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from dpi.materials import MaterialTextures
from dpi.solve.decomposition import Decomposition
from dpi.solve.dps import DPSConfig, start_run
from dpi.solve.dps.gibbs import AlbedoPrior, albedo_draw, level_draw, map_draw, smooth_noise
from dpi.solve.dps.map_solve import Resampling, conjugate_gradients, negative_laplacian, posterior_variance
from dpi.solve.prior_space import resample_env
from dpi.solve.transport import AlbedoLookup, LightTransport, NormalEquations
from test_samplers import LinearProblem, gaussian_prior


def test_posterior_variance_of_a_gaussian_prior():
    # x_t = sqrt(abar) x0 + sqrt(1 - abar) eps with x0 ~ N(0, s^2): Var(x0 | x_t) = 1 / (1/s^2 + abar / (1 - abar))
    for abar, s in ((0.3, 0.5), (0.9, 1.0), (1e-4, 0.5)):
        assert posterior_variance(abar, s) == pytest.approx(1 / (1 / s**2 + abar / (1 - abar)))


@pytest.mark.parametrize("wrap", [True, False])
def test_laplacian_quadratic_form_sums_squared_neighbour_differences(wrap):
    x = torch.randn(1, 4, 8, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    azimuth = (x - torch.roll(x, 1, dims=2)).square().sum() if wrap else (x[:, :, 1:] - x[:, :, :-1]).square().sum()
    polar = (x[:, 1:] - x[:, :-1]).square().sum()
    assert float((x * negative_laplacian(x, wrap)).sum()) == pytest.approx(float(azimuth + polar))


@pytest.mark.parametrize("wrap", [True, False])
def test_smooth_noise_has_the_fields_covariance(wrap):
    shape, smoothness, mass = (1, 3, 4), 2.0, 0.5
    draws = smooth_noise((50000, *shape[1:]), smoothness, wrap, torch.Generator().manual_seed(1), mass)
    empirical = torch.cov(draws.reshape(50000, -1).T)
    units = torch.eye(12, dtype=torch.float64).reshape(12, *shape[1:])
    expected = mass * torch.eye(12, dtype=torch.float64) + smoothness * negative_laplacian(units, wrap).reshape(12, 12)
    torch.testing.assert_close(empirical, expected, atol=0.25, rtol=0)  # ~5 standard errors of a covariance


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


def exact_equations(problem: LinearProblem) -> NormalEquations:
    """The normal equations of LinearProblem's operator (the same for every channel)."""
    a = torch.cat(problem.operators).double()
    y = torch.cat(problem.images).double()
    return NormalEquations((a.T @ a).expand(3, -1, -1).contiguous(), (a.T @ y).T.contiguous(),
                           float(y.square().sum()), y.numel())


def gibbs_run(truth: torch.Tensor, smoothness: float = 0.0, iterations: int = 30):
    height = truth.shape[0]
    init = Decomposition(torch.ones(height, 2 * height, 3), MaterialTextures.constant(4))
    cfg = DPSConfig.from_dict({"sampler": "gibbs", "steps": 10, "radiance_scale": 1.0,
                               "gibbs": {"solver_iterations": iterations, "smoothness": smoothness}})
    return start_run(LinearProblem(truth), gaussian_prior(height), init, cfg, seed=0)


def test_a_map_draw_with_a_weak_prior_recovers_what_the_views_determine():
    """With a negligible prior and no noise the draw is the map an exact operator determines (the exposure
    the draw solves for included)."""
    height = 4
    truth = torch.exp(torch.randn(height, 2 * height, 3, generator=torch.Generator().manual_seed(2)))
    run, state = gibbs_run(truth)
    map_draw(run, state, exact_equations(run.problem), torch.zeros(1, 3, height, 2 * height), variance=1e6,
             sigma2=1e-12)
    found = run.env(torch.exp(state.log_map), state).detach()
    np.testing.assert_allclose(found.numpy(), truth.numpy(), rtol=2e-2)


def test_a_map_draw_without_views_keeps_the_priors_spread():
    """Where the views say nothing, a draw is x0_hat plus a draw of N(0, r_t^2 Q^-1): the prior's spread (without
    the prior's perturbation every draw would be x0_hat itself)."""
    height, variance, smoothness = 4, 0.01, 1.0
    run, state = gibbs_run(torch.ones(height, 2 * height, 3), smoothness, iterations=2)  # a quadratic: exact at once
    silent = NormalEquations(torch.zeros(3, 2 * height ** 2, 2 * height ** 2, dtype=torch.float64),
                             torch.zeros(3, 2 * height ** 2, dtype=torch.float64), 0.0, 1)
    x0_hat = torch.full((1, 3, height, 2 * height), -0.2)
    draws = []
    for _ in range(40):
        with torch.no_grad():
            state.log_map.zero_()
            state.log_exposure.zero_()
        map_draw(run, state, silent, x0_hat, variance, sigma2=1.0)
        solved = state.log_map + state.log_exposure  # the draw before its level moved into the exposure
        draws.append(run.prior.encoding.log_to_prior(solved).detach().reshape(-1))
    z = torch.stack(draws).double()
    units = torch.eye(2 * height ** 2, dtype=torch.float64).reshape(-1, 1, height, 2 * height)
    q = torch.eye(2 * height ** 2, dtype=torch.float64) + smoothness * negative_laplacian(
        units.squeeze(1)).reshape(2 * height ** 2, -1)
    expected = variance * torch.linalg.inv(q).diagonal().mean()
    assert float(z.var(0).mean()) == pytest.approx(float(expected), rel=0.25)
    assert float((z.mean(0) - x0_hat.reshape(-1)).abs().max()) < 0.05  # centred on x0_hat


def albedo_transport(albedo: torch.Tensor, levels: int = 1, seed: int = 0) -> tuple[LightTransport, torch.Tensor]:
    """An exact transport of 3 pixels per texel, each seeing its texel alone, with a map of ones: pixel values
    a_p (A_p 1) + B_p 1 under level 0; the other levels' transports differ."""
    g = torch.Generator().manual_seed(seed)
    size, texels = albedo.shape[0], 8
    pixels = 3 * size * size
    matrix = torch.zeros(2, levels, 2, 3, pixels, texels)
    for level in range(levels):
        slope, offset = torch.rand(3, pixels, texels, generator=g), 0.1 * torch.rand(3, pixels, texels, generator=g)
        matrix[0, level], matrix[1, level] = slope, offset
    rows = torch.arange(pixels)
    lookup = AlbedoLookup(rows, rows % (size * size), torch.ones(pixels, dtype=torch.float64), (pixels, size * size))
    env = torch.ones(2, 4, 3)
    transport = LightTransport(matrix, lookup, torch.zeros(pixels, 3, dtype=torch.float64), 2,
                               [torch.full((size, size, 1), 0.5)] * levels, MaterialTextures.constant(size), pixels,
                               0.0)
    transport.observed = transport.image(env, albedo).double().detach()
    return transport, env


def test_an_albedo_draw_recovers_what_the_views_determine_and_keeps_the_priors_spread_elsewhere():
    from dpi.solve.dps.gibbs import GibbsSettings

    size = 4
    truth = 0.2 + 0.6 * torch.rand(size, size, 3, generator=torch.Generator().manual_seed(3))
    transport, env = albedo_transport(truth)
    settings = GibbsSettings(albedo_std=0.25, albedo_smoothness=1e-4)
    gen = torch.Generator().manual_seed(4)
    found = albedo_draw(settings, transport, env, torch.full_like(truth, 0.5), 0, 1e-10, gen)
    torch.testing.assert_close(found, truth, atol=1e-3, rtol=0)
    narrow = GibbsSettings(albedo_std=0.05, albedo_smoothness=1.0)  # a prior well inside [0, 1]: no clamping
    silent = [albedo_draw(narrow, transport, env, torch.full_like(truth, 0.5), 0, 1e8, gen) for _ in range(300)]
    spread = torch.stack(silent).double()
    prior = AlbedoPrior(size, narrow.albedo_std, narrow.albedo_smoothness)
    precision = torch.stack([prior(torch.eye(size * size, dtype=torch.float64)[i].expand(3, -1))[0]
                             for i in range(size * size)])
    assert float(spread.var(0).mean()) == pytest.approx(float(torch.linalg.inv(precision).diagonal().mean()),
                                                        rel=0.2)
    assert float((spread.mean(0) - 0.5).abs().max()) < 0.05


def test_the_level_that_made_the_views_is_drawn():
    albedo = torch.full((4, 4, 3), 0.5)
    transport, env = albedo_transport(albedo, levels=3)
    transport.observed = transport.halves(env, albedo, 2).mean(0).double().detach()
    gen = torch.Generator().manual_seed(5)
    assert {level_draw(transport, env, albedo, 1e-4, gen) for _ in range(20)} == {2}
    assert len({level_draw(transport, env, albedo, 1e6, gen) for _ in range(60)}) == 3  # no views: any level
