"""The GAN baseline as a posterior method (`gan`): the map is a trained generator's (dpi.prior.gan), inverted as the
paper does, by Pivotal Tuning Inversion (Roich et al. 2022): first the W+ latent is fitted to the views with the
materials, then the generator's weights are tuned around that pivot with the materials.

Each sample starts from its own draw, w = mapping(z) of the seed's z in every style, fitted to the init's map without
rendering (`warmup_iterations`); then `optimize.iterations` Adam steps on the views move W+, a per-channel log gain (the
scene's radiance scale and white balance, which the generator's normalised maps do not carry) and the materials; then
`tune_iterations` steps move the synthesis network's weights, the gain and the materials, the weights' mean squared
distance from the trained ones weighed at `locality_weight` times the data term at the tuning's start (PTI's locality
term, on the weights rather than on outputs near the pivot). The first stage has no prior term: the generator's range is
the prior, as in the paper. The 32 x 64 map is resampled to the problem's size across the sphere.
"""

from __future__ import annotations

import copy
from dataclasses import field
from pathlib import Path

import torch

from dpi.io.settings import Steps, Weight, settings
from dpi.light.sphere_nn import resample_rows
from dpi.prior.gan import GAN, Generator, load_gan
from dpi.prior.baselines import scene_network
from dpi.solve.decomposition import Decomposition
from dpi.solve.init import starting_materials
from dpi.solve.optimize import (LOG_ENV_RANGE, EnvModel, OptimizeConfig, fit_env_model, fit_to_map, flat_config,
                                method_config_from_dict)
from dpi.solve.problem import InverseProblem
from dpi.solve.trace import Trace

WARMUP_RATE = 3e-2
"""Adam rate of W+ and the gain while they fit the init's map"""


@settings
class GANConfig:
    """Settings of the `gan` method."""

    optimize: OptimizeConfig = field(
        default_factory=lambda: OptimizeConfig(iterations=100, views_per_step=2, lr_env=1e-2))
    """Adam settings of the latent stage; lr_env is the rate of W+ and the gain"""
    tune_iterations: Steps = 50
    """Adam steps of the pivotal tuning of the generator's weights (0: the latent stage only)"""
    lr_tune: Weight = 1e-3
    """Adam rate of the generator's weights in the tuning"""
    locality_weight: Weight = 1.0
    """weight of the tuned weights' mean squared distance from the trained ones, per unit of the data term at the
    tuning's start"""
    warmup_iterations: Steps = 200
    """Adam steps fitting W+ to the init's map before the views"""
    checkpoint: str | None = None
    """a generator trained by `dpi train-gan` (None: the shipped one of the scene's family)"""

    @classmethod
    def from_dict(cls, values: dict) -> "GANConfig":
        """Config from a flat `method_params.gan` dict: OptimizeConfig keys plus this class's own."""
        return method_config_from_dict(cls, values)


def generated_log_map(generator: Generator, gan: GAN, w_plus: torch.Tensor, gain: torch.Tensor,
                      height: int) -> torch.Tensor:
    """log L = gain + log G(W+) at `height` rows (H, 2H, 3), clamped to LOG_ENV_RANGE."""
    x = generator.synthesis(w_plus[None])
    log_map = resample_rows(torch.log(gan.encoding.to_radiance(x).clamp_min(1e-30)), height)[0].permute(1, 2, 0)
    return (log_map + gain).clamp(*LOG_ENV_RANGE)


class LatentMap(EnvModel):
    """The latent stage's map: W+ and the gain are its parameters, the generator is the trained one."""

    def __init__(self, gan: GAN, height: int, w_plus: torch.Tensor, gain: torch.Tensor):
        super().__init__()
        self.gan, self.height = gan, height
        self.w_plus = torch.nn.Parameter(w_plus.detach().clone())
        self.gain = torch.nn.Parameter(gain.detach().clone())

    def forward(self) -> torch.Tensor:
        return generated_log_map(self.gan.generator, self.gan, self.w_plus, self.gain, self.height)


class TunedMap(EnvModel):
    """The tuning stage's map: a copy of the synthesis network and the gain are its parameters, W+ is the pivot;
    `penalty` is the weights' mean squared distance from the trained ones."""

    def __init__(self, latent: LatentMap):
        super().__init__()
        self.gan, self.height = latent.gan, latent.height
        self.generator = copy.deepcopy(latent.gan.generator)
        del self.generator.mapping  # not tuned: W+ is fixed
        self.register_buffer("w_plus", latent.w_plus.detach().clone())
        self.gain = torch.nn.Parameter(latent.gain.detach().clone())
        self.trained = [q.detach().clone() for q in self.generator.parameters()]

    def forward(self) -> torch.Tensor:
        return generated_log_map(self.generator, self.gan, self.w_plus, self.gain, self.height)

    def penalty(self) -> torch.Tensor:
        """The tuned weights' mean squared distance from the trained ones."""
        tuned = list(self.generator.parameters())
        return sum((p - q).square().sum() for p, q in zip(tuned, self.trained)) / sum(q.numel() for q in self.trained)


def gan_sample(problem: InverseProblem, init: Decomposition, cfg: GANConfig, seed: int,
               progress: bool = True, checkpoint: Path | None = None) -> Decomposition:
    """One `gan` sample (module notes; `checkpoint`: the tuning's resume file; the latent stage is rerun)."""
    target = init.env.clamp_min(1e-6).log()
    gan = scene_network(problem.capture.options, cfg.checkpoint, "gan", load_gan)
    generator = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        z = torch.randn((1, gan.generator.network.latent), generator=generator)
        w_plus = gan.generator.mapping(z).expand(gan.generator.styles, -1)
    model = LatentMap(gan, target.shape[0], w_plus, torch.zeros(3))
    with torch.no_grad():
        model.gain.copy_((target - model()).mean(dim=(0, 1)))
    warmup_error = fit_to_map(model, target, cfg.warmup_iterations, WARMUP_RATE)
    trace = Trace(info={"method": "gan", "seed": seed, "config": flat_config(cfg), "prior_weight": 0.0,
                        "prior": "the generator's range (latent stage), locality of the tuned weights (tuning)",
                        "warmup_error": warmup_error, "locality_weight": cfg.locality_weight})
    log_env, materials = fit_env_model(problem, model, starting_materials(init), cfg.optimize, seed, trace,
                                       progress=progress)
    if cfg.tune_iterations:
        tuned = TunedMap(model)
        tuning = OptimizeConfig(**{**vars(cfg.optimize), "iterations": cfg.tune_iterations, "lr_env": cfg.lr_tune})
        with torch.no_grad():
            data0 = float(problem.data_loss(tuned().exp(), materials, problem.train_ids, seed))
        trace.info["tune_weight"] = weight = cfg.locality_weight * data0
        log_env, materials = fit_env_model(problem, tuned, materials, tuning, seed + 1, trace,
                                           prior=lambda env: tuned.penalty(), prior_weight=weight, progress=progress,
                                           checkpoint=checkpoint)
    return Decomposition(log_env.exp(), materials, trace)
