"""Gaussian diffusion (DDPM) on prior-space images, as in guided-diffusion's `gaussian_diffusion.py`.

Schedules are float64 arrays indexed by timestep. A respaced schedule (fewer steps) is the same
class built from a subset of the base timesteps, with `timestep_map` translating its indices to
the base indices the network was trained on (guided-diffusion's `respace.py`). The network
predicts eps; with learned sigma it also predicts v in [-1, 1], which interpolates the log
variance between beta_t and the posterior variance beta~_t (Nichol & Dhariwal 2021).
Per-step random horizontal rolls (paper Eq. 15) make sampled equirect maps seamless at the wrap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch
from torch import nn

Model = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]


def linear_betas(num_timesteps: int = 1000) -> np.ndarray:
    """guided-diffusion's linear schedule: 1e-4..0.02 for 1000 steps, scaled by 1000 / num_timesteps."""
    scale = 1000 / num_timesteps
    return np.linspace(scale * 1e-4, scale * 0.02, num_timesteps, dtype=np.float64)


def evenly_spaced_timesteps(num_timesteps: int, count: int) -> list[int]:
    """`count` base timesteps from 0 to num_timesteps-1, evenly spaced (guided-diffusion `space_timesteps`)."""
    if not 1 <= count <= num_timesteps:
        raise ValueError(f"cannot pick {count} steps out of {num_timesteps}")
    if count == 1:
        return [0]
    stride = (num_timesteps - 1) / (count - 1)
    return sorted({round(i * stride) for i in range(count)})


@dataclass
class Diffusion:
    """A DDPM schedule: betas (T,) and everything derived from them, plus the base timestep of each step."""

    betas: np.ndarray
    learn_sigma: bool = True
    timestep_map: np.ndarray | None = None

    def __post_init__(self) -> None:
        b = np.asarray(self.betas, dtype=np.float64)
        self.betas = b
        self.num_timesteps = len(b)
        if self.timestep_map is None:
            self.timestep_map = np.arange(self.num_timesteps)
        self.alphas_cumprod = np.cumprod(1.0 - b)
        self.alphas_cumprod_prev = np.append(1.0, self.alphas_cumprod[:-1])
        self.posterior_variance = b * (1.0 - self.alphas_cumprod_prev) / (1.0 - self.alphas_cumprod)
        self.posterior_log_variance_clipped = np.log(np.append(self.posterior_variance[1], self.posterior_variance[1:]))
        self.posterior_mean_coef1 = b * np.sqrt(self.alphas_cumprod_prev) / (1.0 - self.alphas_cumprod)
        self.posterior_mean_coef2 = (1.0 - self.alphas_cumprod_prev) * np.sqrt(1.0 - b) / (1.0 - self.alphas_cumprod)
        self.log_betas = np.log(b)
        self._tables: dict[tuple[int, str], torch.Tensor] = {}

    def table(self, arr: np.ndarray, device: torch.device) -> torch.Tensor:
        """`arr` (one of this schedule's arrays) as a float64 tensor on `device`, copied there once:
        a host-to-device copy per lookup would synchronise every training step on a GPU."""
        key = (id(arr), str(device))
        if key not in self._tables:
            self._tables[key] = torch.as_tensor(arr, device=device)
        return self._tables[key]


def base_diffusion(num_timesteps: int = 1000, learn_sigma: bool = True) -> Diffusion:
    """The training schedule: linear betas over `num_timesteps` steps."""
    return Diffusion(linear_betas(num_timesteps), learn_sigma)


def respaced(base: Diffusion, use_timesteps: list[int]) -> Diffusion:
    """Schedule over a subset of base timesteps with betas recomputed so alpha_bar matches at kept steps."""
    keep = sorted(set(use_timesteps))
    abar = base.alphas_cumprod[keep]
    betas = 1.0 - abar / np.append(1.0, abar[:-1])
    return Diffusion(betas, base.learn_sigma, base.timestep_map[keep])


def extract(diffusion: Diffusion, arr: np.ndarray, t: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    """arr[t] (B,) of one of the schedule's arrays, broadcast to the shape of `like` (B, ...), in its dtype."""
    out = diffusion.table(arr, t.device)[t].to(like.dtype)
    return out.reshape(-1, *([1] * (like.ndim - 1)))


def model_timesteps(diffusion: Diffusion, t: torch.Tensor) -> torch.Tensor:
    """Base timesteps (B,) the network is conditioned on for schedule indices t (B,)."""
    return diffusion.table(diffusion.timestep_map, t.device)[t]


def q_sample(diffusion: Diffusion, x0: torch.Tensor, t: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
    """x_t ~ q(x_t | x_0) (B, C, H, W): sqrt(abar_t) x_0 + sqrt(1 - abar_t) noise."""
    abar = extract(diffusion, diffusion.alphas_cumprod, t, x0)
    return abar.sqrt() * x0 + (1 - abar).sqrt() * noise


def predict_x0(diffusion: Diffusion, x_t: torch.Tensor, t: torch.Tensor, eps: torch.Tensor) -> torch.Tensor:
    """x0_hat (B, C, H, W) = (x_t - sqrt(1 - abar_t) eps) / sqrt(abar_t), not clamped."""
    abar = extract(diffusion, diffusion.alphas_cumprod, t, x_t)
    return (x_t - (1 - abar).sqrt() * eps) / abar.sqrt()


def q_posterior_mean_variance(diffusion: Diffusion, x0: torch.Tensor, x_t: torch.Tensor,
                              t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean (B, C, H, W) and clipped log variance (B, 1, 1, 1) of q(x_{t-1} | x_t, x_0)."""
    mean = extract(diffusion, diffusion.posterior_mean_coef1, t, x_t) * x0 + extract(diffusion, diffusion.posterior_mean_coef2, t, x_t) * x_t
    return mean, extract(diffusion, diffusion.posterior_log_variance_clipped, t, x_t)


def model_log_variance(diffusion: Diffusion, t: torch.Tensor, x_t: torch.Tensor,
                       v: torch.Tensor | None) -> torch.Tensor:
    """log sigma_t^2: learned range frac log beta_t + (1 - frac) log beta~_t with frac = (v + 1) / 2, or fixed log beta~_t."""
    min_log = extract(diffusion, diffusion.posterior_log_variance_clipped, t, x_t)
    if v is None:
        return min_log.expand_as(x_t)
    max_log = extract(diffusion, diffusion.log_betas, t, x_t)
    frac = (v + 1) / 2
    return frac * max_log + (1 - frac) * min_log


def split_model_output(diffusion: Diffusion, output: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
    """(eps, v) from the network output (B, 3 or 6, H, W); v is None without learned sigma."""
    if diffusion.learn_sigma:
        eps, v = output.chunk(2, dim=1)
        return eps, v
    return output, None


def p_mean_variance(diffusion: Diffusion, output: torch.Tensor, x_t: torch.Tensor, t: torch.Tensor,
                    clip: bool = True) -> dict[str, torch.Tensor]:
    """Mean, log variance (B, C, H, W) of p(x_{t-1} | x_t) and x0_hat, from the network output at (x_t, t)."""
    eps, v = split_model_output(diffusion, output)
    x0 = predict_x0(diffusion, x_t, t, eps)
    if clip:
        x0 = x0.clamp(-1, 1)
    mean, _ = q_posterior_mean_variance(diffusion, x0, x_t, t)
    return {"mean": mean, "log_variance": model_log_variance(diffusion, t, x_t, v), "x0": x0, "eps": eps}


def normal_kl(mean1: torch.Tensor, logvar1: torch.Tensor, mean2: torch.Tensor, logvar2: torch.Tensor) -> torch.Tensor:
    """KL(N(mean1, e^logvar1) || N(mean2, e^logvar2)) elementwise, in nats."""
    return 0.5 * (-1.0 + logvar2 - logvar1 + torch.exp(logvar1 - logvar2) + (mean1 - mean2) ** 2 * torch.exp(-logvar2))


def discretized_gaussian_log_likelihood(x: torch.Tensor, mean: torch.Tensor, log_scale: torch.Tensor) -> torch.Tensor:
    """log p(x) elementwise for x in [-1, 1] quantised to 256 levels under N(mean, e^(2 log_scale))."""
    def cdf(z: torch.Tensor) -> torch.Tensor:
        return 0.5 * (1.0 + torch.tanh(math.sqrt(2.0 / math.pi) * (z + 0.044715 * z**3)))

    inv_std = torch.exp(-log_scale)
    cdf_plus = cdf(inv_std * (x - mean + 1 / 255))
    cdf_minus = cdf(inv_std * (x - mean - 1 / 255))
    log_cdf_plus = cdf_plus.clamp(min=1e-12).log()
    log_one_minus_cdf_min = (1 - cdf_minus).clamp(min=1e-12).log()
    log_delta = (cdf_plus - cdf_minus).clamp(min=1e-12).log()
    return torch.where(x < -0.999, log_cdf_plus, torch.where(x > 0.999, log_one_minus_cdf_min, log_delta))


def vlb_term(diffusion: Diffusion, output: torch.Tensor, x0: torch.Tensor, x_t: torch.Tensor,
             t: torch.Tensor) -> torch.Tensor:
    """Variational bound term L_t (B,) in bits/dim: KL(q || p) for t > 0, decoder NLL at t = 0."""
    true_mean, true_logvar = q_posterior_mean_variance(diffusion, x0, x_t, t)
    p = p_mean_variance(diffusion, output, x_t, t, clip=False)
    kl = normal_kl(true_mean, true_logvar, p["mean"], p["log_variance"]).mean(dim=(1, 2, 3)) / math.log(2.0)
    nll = -discretized_gaussian_log_likelihood(x0, p["mean"], 0.5 * p["log_variance"]).mean(dim=(1, 2, 3)) / math.log(2.0)
    return torch.where(t == 0, nll, kl)


def training_losses(diffusion: Diffusion, model: Model, x0: torch.Tensor, t: torch.Tensor,
                    noise: torch.Tensor) -> dict[str, torch.Tensor]:
    """Per-sample losses (B,): 'mse' on eps, 'vb' (learned sigma; mean frozen, x T/1000) and their sum 'loss'."""
    x_t = q_sample(diffusion, x0, t, noise)
    output = model(x_t, model_timesteps(diffusion, t))
    eps, v = split_model_output(diffusion, output)
    losses = {"mse": ((eps - noise) ** 2).mean(dim=(1, 2, 3))}
    if v is not None:
        frozen = torch.cat([eps.detach(), v], dim=1)
        losses["vb"] = vlb_term(diffusion, frozen, x0, x_t, t) * diffusion.num_timesteps / 1000.0
    losses["loss"] = losses["mse"] + losses.get("vb", 0.0)
    return losses


def random_roll_shift(width: int, generator: torch.Generator | None) -> int:
    """A column shift drawn uniformly from [0, width)."""
    device = generator.device if generator is not None else None
    return int(torch.randint(0, width, (1,), generator=generator, device=device).item())


def model_output_with_random_roll(model: Model, x_t: torch.Tensor, t: torch.Tensor,
                                  generator: torch.Generator | None) -> torch.Tensor:
    """Network output (B, C', H, W) computed on x_t rolled by a random azimuth shift, rolled back (Eq. 15)."""
    shift = random_roll_shift(x_t.shape[-1], generator)
    return torch.roll(model(torch.roll(x_t, shift, dims=-1), t), -shift, dims=-1)


def eps_with_random_roll(model: Model, x_t: torch.Tensor, t: torch.Tensor,
                         generator: torch.Generator | None = None) -> torch.Tensor:
    """eps (B, 3, H, W) = roll^-1(eps_theta(roll(x_t), t)) with a fresh random roll (paper Eq. 15).

    `t` are the network's (base) timesteps; use `model_timesteps` to map respaced indices.
    """
    output = model_output_with_random_roll(model, x_t, t, generator)
    return output[:, : x_t.shape[1]]


def p_sample_step(diffusion: Diffusion, model: Model, x_t: torch.Tensor, i: int, generator: torch.Generator | None,
                  random_roll: bool = True) -> dict[str, torch.Tensor]:
    """One ancestral step x_t -> x_{t-1} (B, C, H, W) at schedule index i; returns 'sample', 'x0', 'eps'."""
    t = torch.full((x_t.shape[0],), i, device=x_t.device, dtype=torch.long)
    base_t = model_timesteps(diffusion, t)
    output = model_output_with_random_roll(model, x_t, base_t, generator) if random_roll else model(x_t, base_t)
    p = p_mean_variance(diffusion, output, x_t, t)
    noise = torch.randn(x_t.shape, generator=generator, device=x_t.device, dtype=x_t.dtype) if i > 0 else 0.0
    sample = p["mean"] + torch.exp(0.5 * p["log_variance"]) * noise
    return {"sample": sample, "x0": p["x0"], "eps": p["eps"]}


@torch.no_grad()
def sample(diffusion: Diffusion, model: nn.Module, shape: tuple[int, int, int, int],
           generator: torch.Generator | None = None, random_roll: bool = True,
           device: str | torch.device = "cpu") -> torch.Tensor:
    """Unconditional samples x_0 (B, C, H, W) in [-1, 1] by ancestral sampling from x_T ~ N(0, I)."""
    x = torch.randn(shape, generator=generator, device=device)
    for i in reversed(range(diffusion.num_timesteps)):
        x = p_sample_step(diffusion, model, x, i, generator, random_roll)["sample"]
    return x.clamp(-1, 1)
