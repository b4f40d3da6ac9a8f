"""Naturalness of an env map under the scene's own diffusion prior, with no external weights.

A map the prior finds likely is one its network denoises well: the eps-prediction error
E_{t, eps} ||eps_theta(sqrt(abar_t) x0 + sqrt(1 - abar_t) eps, t) - eps||^2 is, up to per-step
weights and constants, the diffusion model's variational bound on -log p(x0). The score is minus
that error (the prior's training `mse` term), averaged over fixed timesteps and fixed noise draws
(the same for every map, so scores compare), with the map in the prior's training normalisation:
resampled to the prior's resolution, divided by the scale that brings its median luminance to
`median_target`, through the prior's encoding. Higher is more natural.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from dpi.io.images import resize
from dpi.prior.data import radiance_scale
from dpi.prior.diffusion import training_losses
from dpi.prior.sample import Prior


@dataclass(frozen=True)
class NaturalnessConfig:
    """Which noise levels and draws the denoising error is averaged over."""

    timesteps: tuple[int, ...] = (50, 200, 400, 600)
    """training timesteps (of the prior's schedule) the map is noised to"""
    seeds: tuple[int, ...] = (0, 1)
    """seeds of the Gaussian noise drawn for each timestep"""


def prior_image(env: np.ndarray, prior: Prior) -> torch.Tensor:
    """An HDR env map (H, W, 3) as the prior saw its training maps: (3, h, 2h) in [-1, 1]."""
    radiance = resize(torch.from_numpy(np.ascontiguousarray(env, dtype=np.float32)), prior.height, 2 * prior.height)
    radiance = radiance.permute(2, 0, 1)
    return prior.encoding.with_scale(radiance_scale(radiance, prior.median_target)).to_prior(radiance)


@torch.no_grad()
def naturalness(env: np.ndarray, prior: Prior, cfg: NaturalnessConfig = NaturalnessConfig()) -> float:
    """Minus the (CPU) prior's mean eps-prediction MSE on an HDR env map (H, W, 3); higher is more natural."""
    x0 = prior_image(env, prior)
    noise = torch.stack([torch.randn(x0.shape, generator=torch.Generator().manual_seed(s))
                         for _ in cfg.timesteps for s in cfg.seeds])
    t = torch.tensor([t for t in cfg.timesteps for _ in cfg.seeds])
    losses = training_losses(prior.diffusion, prior.model, x0.expand(len(t), *x0.shape), t, noise)
    return -float(losses["mse"].mean())
