"""RENI as a posterior method (`reni`, Gardner et al. 2022): the map is a trained RENI decoder's field of a latent Z
(dpi.prior.reni), and Z is fitted to the views with the materials under its N(0, I) prior.

Each sample draws its own Z from the latent prior (the seed), fits it to the init's map without rendering
(`warmup_iterations`, the latent prior held), then fits Z, a per-channel log gain (the scene's radiance scale and
white balance, which the decoder's normalised maps do not carry) and the materials to the views. The latent prior's
weight is set so that it and the data term have the same magnitude at the start, times `prior_weight_ratio`, as the
hand-made priors' (dpi.solve.classic). The decoder stays fixed: RENI's light is always a map it can decode.
"""

from __future__ import annotations

from dataclasses import field
from pathlib import Path

import torch

from dpi.io.settings import Steps, Weight, settings
from dpi.prior.reni import RENI, load_reni
from dpi.prior.baselines import scene_network
from dpi.solve.classic import balanced_weight
from dpi.solve.decomposition import Decomposition
from dpi.solve.init import starting_materials
from dpi.solve.optimize import (LOG_ENV_RANGE, EnvModel, OptimizeConfig, fit_env_model, fit_to_map, flat_config,
                                method_config_from_dict)
from dpi.solve.problem import InverseProblem
from dpi.solve.trace import Trace

WARMUP_RATE = 3e-2
"""Adam rate of the latent and the gain while they fit the init's map"""


@settings
class RENIConfig:
    """Settings of the `reni` method."""

    optimize: OptimizeConfig = field(
        default_factory=lambda: OptimizeConfig(iterations=150, views_per_step=2, lr_env=1e-2))
    """Adam settings; lr_env is the rate of the latent and the gain"""
    prior_weight_ratio: Weight = 1.0
    """the latent prior's weight over the one that matches the data term's magnitude at the start"""
    warmup_iterations: Steps = 200
    """Adam steps fitting the latent to the init's map before the views (0: the prior's draw as it is)"""
    checkpoint: str | None = None
    """a RENI decoder trained by `dpi train-reni` (None: the shipped one of the scene's family)"""

    @classmethod
    def from_dict(cls, values: dict) -> "RENIConfig":
        """Config from a flat `method_params.reni` dict: OptimizeConfig keys plus this class's own."""
        return method_config_from_dict(cls, values)


class RENIField(EnvModel):
    """log L = gain + RENI(Z) at the problem's map size (H, 2H, 3); `penalty` is the latent's negative log prior."""

    def __init__(self, reni: RENI, height: int, z: torch.Tensor, gain: torch.Tensor):
        super().__init__()
        self.reni, self.height = reni, height
        self.z = torch.nn.Parameter(z.detach().clone())
        self.gain = torch.nn.Parameter(gain.detach().clone())

    def forward(self) -> torch.Tensor:
        """The decoded map's log radiance, clamped to LOG_ENV_RANGE."""
        return (self.reni.log_radiance(self.z, self.height) + self.gain).clamp(*LOG_ENV_RANGE)

    def penalty(self) -> torch.Tensor:
        """The latent's negative log prior per number (N(0, latent_std^2 I), dpi.prior.reni)."""
        return 0.5 * (self.z / self.reni.latent_std).square().mean()


def reni_sample(problem: InverseProblem, init: Decomposition, cfg: RENIConfig, seed: int,
                progress: bool = True, checkpoint: Path | None = None) -> Decomposition:
    """One `reni` sample (module notes; `checkpoint`: the joint fit's resume file; the warm-up is rerun)."""
    target = init.env.clamp_min(1e-6).log()
    reni = scene_network(problem.capture.options, cfg.checkpoint, "reni", load_reni)
    generator = torch.Generator().manual_seed(seed)
    z = reni.draw(1, generator)[0]
    with torch.no_grad():
        gain = (target - reni.log_radiance(z, target.shape[0])).mean(dim=(0, 1))
    model = RENIField(reni, target.shape[0], z, gain)
    warmup_error = fit_to_map(model, target, cfg.warmup_iterations, WARMUP_RATE, penalty=model.penalty)
    materials = starting_materials(init)
    with torch.no_grad():
        data0 = float(problem.data_loss(model().exp(), materials, problem.train_ids, seed))
        weight = balanced_weight(data0, float(model.penalty()), cfg.prior_weight_ratio)
    trace = Trace(info={"method": "reni", "seed": seed, "config": flat_config(cfg), "prior_weight": weight,
                        "prior": "RENI latent N(0, latent_std^2 I)", "latent_std": reni.latent_std,
                        "latents": reni.decoder.network.latents, "warmup_error": warmup_error})
    log_env, materials = fit_env_model(problem, model, materials, cfg.optimize, seed, trace,
                                       prior=lambda env: model.penalty(), prior_weight=weight,
                                       progress=progress, checkpoint=checkpoint)
    return Decomposition(log_env.exp(), materials, trace)
