"""Diffusion prior on equirectangular HDR environment maps (guided-diffusion UNet + DDPM).

What a posterior sampler needs:
    prior = load_default_prior("outdoor")            # or load_prior(path); .model, .diffusion, .encoding
    diffusion = prior.schedule(steps)                 # respaced schedule (None: all 1000 steps)
    t_net = model_timesteps(diffusion, t)             # schedule index -> network timestep
    eps = eps_with_random_roll(prior.model, x_t, t_net, generator)          # Eq. 15
    out = model_output_with_random_roll(prior.model, x_t, t_net, generator)  # eps and v (learned sigma)
    x0_hat = predict_x0(diffusion, x_t, t, eps).clamp(-1, 1)
    step = p_mean_variance(diffusion, out, x_t, t)     # 'mean', 'log_variance', 'x0', 'eps'
    L = prior.encoding.with_scale(s).to_radiance(x0_hat)   # s: per-scene radiance scale
At s = 1 a map has median luminance `prior.median_target`; `radiance_scale(L, prior.median_target)`
gives the s that puts a radiance map L (e.g. the initialisation) on that convention.
"""

from dpi.prior.data import radiance_scale
from dpi.prior.diffusion import (Diffusion, eps_with_random_roll, model_output_with_random_roll, model_timesteps,
                                 p_mean_variance, p_sample_step, predict_x0)
from dpi.prior.sample import Prior, load_default_prior, load_prior

__all__ = [
    "Diffusion", "Prior", "eps_with_random_roll", "load_default_prior", "load_prior", "model_output_with_random_roll",
    "model_timesteps", "p_mean_variance", "p_sample_step", "predict_x0", "radiance_scale",
]
