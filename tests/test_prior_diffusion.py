"""DDPM schedule, respacing, posterior quantities, losses, random-roll eps and sampling."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from dpi.prior.diffusion import (base_diffusion, eps_with_random_roll, evenly_spaced_timesteps, linear_betas,
                                 model_log_variance, model_timesteps, p_mean_variance, predict_x0, q_sample,
                                 random_roll_shift, respaced, sample, training_losses)
from dpi.prior.unet import SMALL_CONFIGS, UNetModel


def test_linear_schedule_known_values() -> None:
    betas = linear_betas(1000)
    assert betas[0] == pytest.approx(1e-4) and betas[-1] == pytest.approx(0.02)
    assert linear_betas(100)[-1] == pytest.approx(0.2)  # guided-diffusion scales by 1000 / T
    abar = base_diffusion().alphas_cumprod
    assert np.all(np.diff(abar) < 0) and 0 < abar[-1] < 1e-4 and abar[0] == pytest.approx(1 - 1e-4)


def test_evenly_spaced_timesteps() -> None:
    assert evenly_spaced_timesteps(1000, 4) == [0, 333, 666, 999]
    assert evenly_spaced_timesteps(10, 10) == list(range(10))
    with pytest.raises(ValueError):
        evenly_spaced_timesteps(10, 11)


def test_respacing_with_all_steps_is_the_original() -> None:
    base = base_diffusion()
    full = respaced(base, list(range(1000)))
    np.testing.assert_allclose(full.betas, base.betas, rtol=1e-9)
    np.testing.assert_array_equal(full.timestep_map, np.arange(1000))


def test_respacing_keeps_alpha_bar_at_kept_steps() -> None:
    base = base_diffusion()
    keep = evenly_spaced_timesteps(1000, 25)
    short = respaced(base, keep)
    assert short.num_timesteps == 25
    np.testing.assert_allclose(short.alphas_cumprod, base.alphas_cumprod[keep], rtol=1e-9)
    assert model_timesteps(short, torch.tensor([0, 24])).tolist() == [0, 999]


def test_predict_x0_inverts_q_sample() -> None:
    d = base_diffusion()
    x0, noise = torch.rand(3, 3, 4, 8) * 2 - 1, torch.randn(3, 3, 4, 8)
    t = torch.tensor([0, 500, 999])
    x_t = q_sample(d, x0.double(), t, noise.double())
    torch.testing.assert_close(predict_x0(d, x_t, t, noise.double()), x0.double(), rtol=1e-6, atol=1e-6)


def test_exact_eps_gives_the_true_posterior_mean() -> None:
    d = base_diffusion(learn_sigma=False)
    x0, noise, t = torch.rand(1, 3, 4, 8).double() * 2 - 1, torch.randn(1, 3, 4, 8).double(), torch.tensor([10])
    x_t = q_sample(d, x0, t, noise)
    p = p_mean_variance(d, noise, x_t, t, clip=False)
    c1, c2 = d.posterior_mean_coef1[10], d.posterior_mean_coef2[10]
    torch.testing.assert_close(p["mean"], c1 * x0 + c2 * x_t)


def test_learned_variance_spans_posterior_to_beta() -> None:
    d = base_diffusion()
    x, t = torch.zeros(1, 3, 2, 4), torch.tensor([100])
    lo = model_log_variance(d, t, x, -torch.ones_like(x))
    hi = model_log_variance(d, t, x, torch.ones_like(x))
    assert torch.allclose(lo, torch.full_like(x, d.posterior_log_variance_clipped[100]))
    assert torch.allclose(hi, torch.full_like(x, np.log(d.betas[100])))


def test_training_losses_are_finite_per_sample() -> None:
    d = base_diffusion()
    x0 = torch.rand(4, 3, 16, 32) * 2 - 1
    losses = training_losses(d, UNetModel(SMALL_CONFIGS["tiny"]), x0, torch.tensor([0, 1, 500, 999]),
                             torch.randn_like(x0))
    assert losses["loss"].shape == (4,) and torch.isfinite(losses["loss"]).all() and "vb" in losses


def test_eps_with_random_roll_rolls_back_exactly() -> None:
    ramp = torch.linspace(0, 1, 16)

    def position_dependent(x: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        return x * ramp

    x = torch.randn(2, 3, 8, 16)
    shift = random_roll_shift(16, torch.Generator().manual_seed(7))
    eps = eps_with_random_roll(position_dependent, x, torch.tensor([1, 1]), torch.Generator().manual_seed(7))
    torch.testing.assert_close(eps, x * torch.roll(ramp, -shift))
    # a roll-equivariant network is unchanged by the random roll
    eps_eq = eps_with_random_roll(lambda x, t: 2 * x, x, torch.tensor([1, 1]), torch.Generator().manual_seed(3))
    torch.testing.assert_close(eps_eq, 2 * x)


def test_eps_with_random_roll_returns_eps_channels_only() -> None:
    model = UNetModel(SMALL_CONFIGS["tiny"])
    eps = eps_with_random_roll(model, torch.randn(1, 3, 16, 32), torch.tensor([10]))
    assert eps.shape == (1, 3, 16, 32)


@pytest.mark.parametrize("random_roll", [True, False])
def test_unconditional_sampling_tiny(random_roll: bool) -> None:
    model = UNetModel(SMALL_CONFIGS["tiny"]).eval()
    torch.nn.init.normal_(model.out[2].weight, std=0.05)
    d = respaced(base_diffusion(), evenly_spaced_timesteps(1000, 4))
    x = sample(d, model, (1, 3, 16, 32), torch.Generator().manual_seed(0), random_roll=random_roll)
    assert x.shape == (1, 3, 16, 32) and torch.isfinite(x).all()
    assert x.min() >= -1 and x.max() <= 1


def test_sampling_is_reproducible_with_a_seed() -> None:
    model = UNetModel(SMALL_CONFIGS["tiny"]).eval()
    d = respaced(base_diffusion(), evenly_spaced_timesteps(1000, 3))
    a = sample(d, model, (1, 3, 16, 32), torch.Generator().manual_seed(5))
    b = sample(d, model, (1, 3, 16, 32), torch.Generator().manual_seed(5))
    assert torch.equal(a, b)


@pytest.mark.parametrize("steps", [10, 1000])
def test_sampling_with_the_exact_eps_recovers_a_point_mass(steps: int) -> None:
    base = base_diffusion()
    x_star = torch.rand(1, 3, 4, 8) * 2 - 1

    def oracle(x: torch.Tensor, t: torch.Tensor) -> torch.Tensor:  # optimal eps when the data is x_star only
        abar = torch.as_tensor(base.alphas_cumprod)[t].float().reshape(-1, 1, 1, 1)
        eps = (x - abar.sqrt() * x_star) / (1 - abar).sqrt()
        return torch.cat([eps, torch.zeros_like(eps)], dim=1)

    d = respaced(base, evenly_spaced_timesteps(1000, steps))
    x = sample(d, oracle, (2, 3, 4, 8), torch.Generator().manual_seed(0), random_roll=False)
    torch.testing.assert_close(x, x_star.expand(2, -1, -1, -1), atol=1e-4, rtol=0)
