"""Score distillation (`sds`): the paper's ablation that uses the diffusion prior as a loss, not a sampler.

The map is a free image x in the prior's space, started from the init map. Every iteration adds
to the rendering-loss gradient the score-distillation gradient (Poole et al. 2022)
  grad_sds = w * (eps_theta(x_t, t) - eps),  x_t = sqrt(abar_t) x + sqrt(1 - abar_t) eps,
for a random t and eps (no backpropagation through the network), and Adam updates x and the
materials. `w` is set so the two gradients have the same max-abs at the start (times
`SDS_WEIGHT_RATIO`).
"""

from __future__ import annotations

from typing import Any

import torch
from tqdm import tqdm

from dpi.io.settings import Count, Rate, Steps, settings, settings_from_dict
from dpi.prior.diffusion import model_output_with_random_roll, q_sample, split_model_output
from dpi.prior.sample import Prior
from dpi.solve.decomposition import Decomposition
from dpi.solve.init import starting_materials
from dpi.solve.materials import MaterialRates
from dpi.solve.optimize import all_finite
from dpi.solve.prior_space import estimate_radiance_scale, prior_to_env
from dpi.solve.problem import InverseProblem
from dpi.solve.trace import Trace

SDS_WEIGHT_RATIO = 1.0


T_RANGE = (0.02, 0.98)
"""smallest and largest diffusion time drawn, as fractions of the schedule"""


@settings
class SDSConfig(MaterialRates):
    """Settings of the `sds` ablation (the textures' rates: MaterialRates)."""

    iterations: Steps = 150
    views_per_step: Count = 1
    lr_map: Rate = 2e-2
    """Adam learning rate on the prior-space map x"""

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> "SDSConfig":
        """Config from a `method_params.sds` entry."""
        return settings_from_dict(cls, values)


def sds_gradient(prior: Prior, x: torch.Tensor, generator: torch.Generator, t_min: float, t_max: float) -> torch.Tensor:
    """(eps_theta(x_t, t) - eps) for one random t and eps: the score-distillation direction on x."""
    T = prior.diffusion.num_timesteps
    t = torch.randint(int(t_min * T), int(t_max * T), (1,), generator=generator)
    eps = torch.randn(x.shape, generator=generator)
    with torch.no_grad():
        x_t = q_sample(prior.diffusion, x, t, eps)
        eps_pred, _ = split_model_output(prior.diffusion, model_output_with_random_roll(prior.model, x_t, t, generator))
    return eps_pred - eps


def sds_sample(problem: InverseProblem, prior: Prior, init: Decomposition, cfg: SDSConfig, seed: int,
               progress: bool = True, radiance_scale: float | None = None) -> Decomposition:
    """One `sds` decomposition: the map optimised under rendering loss + score distillation (`radiance_scale` as
    dps_sample's)."""
    generator = torch.Generator().manual_seed(seed)
    scale = radiance_scale or estimate_radiance_scale(init.env, prior)
    height = problem.settings.env_height
    start = torch.nn.functional.interpolate(init.env.permute(2, 0, 1)[None], size=(prior.height, 2 * prior.height),
                                            mode="area")
    x = prior.encoding.with_scale(scale).to_prior(start).clamp(-0.999, 0.999).requires_grad_(True)
    materials = starting_materials(init)
    free = [x, *(t.requires_grad_(True) for _, t in materials.items())]
    optimizer = torch.optim.Adam([{"params": [x], "lr": cfg.lr_map},
                                  *({"params": [t], "lr": cfg.rate(name)} for name, t in materials.items())])
    trace = Trace(info={"method": "sds", "seed": seed, "radiance_scale": scale, "config": vars(cfg).copy()})
    weight = None
    for step in tqdm(range(cfg.iterations), desc="sds", disable=not progress, mininterval=2.0):
        t0 = trace.seconds
        views = problem.sample_views(cfg.views_per_step, generator)
        loss = problem.data_loss(prior_to_env(x, prior, scale, height), materials, views, seed=seed * 7919 + step)
        optimizer.zero_grad()
        if not torch.isfinite(loss):
            trace.skip(step, "non-finite loss")
            continue
        loss.backward()
        direction = sds_gradient(prior, x.detach(), generator, *T_RANGE)
        if weight is None:
            weight = SDS_WEIGHT_RATIO * float(x.grad.abs().max()) / max(float(direction.abs().max()), 1e-12)
            trace.info["sds_weight"] = weight
        x.grad += weight * direction
        if not all_finite(free):
            trace.skip(step, "non-finite gradient")
            continue
        optimizer.step()
        with torch.no_grad():
            x.clamp_(-1, 1)
        problem.constrain_(materials)
        trace.record(step=step, loss=loss.item(), seconds=round(trace.seconds - t0, 4))
    env = prior_to_env(x.detach(), prior, scale, height)
    return Decomposition(env, materials.detached(), trace)
