"""Optimisation-based posterior "samples" for the hand-crafted priors (none, global_norm, ...).

Each sample starts from the initialisation's roughness and metallic, a reset (grey) albedo and
the init map perturbed by log-normal noise drawn from the sample's seed, then fits map and
materials jointly with the prior's penalty. The penalty weight is set so that both loss terms
have the same magnitude at the start (times `PRIOR_WEIGHT_RATIO`).
"""

from __future__ import annotations

from dataclasses import field
from pathlib import Path

import torch

from dpi.io.settings import Weight, settings
from dpi.solve.decomposition import Decomposition
from dpi.solve.init import starting_materials
from dpi.solve.optimize import OptimizeConfig, fit, flat_config, method_config_from_dict
from dpi.solve.priors import make_prior
from dpi.solve.problem import InverseProblem
from dpi.solve.trace import Trace

PRIOR_WEIGHT_RATIO = 1.0
"""prior weight relative to the balanced one (1: equal magnitude at the start)"""


@settings
class ClassicConfig:
    """Settings of an optimisation-based prior method."""

    optimize: OptimizeConfig = field(default_factory=lambda: OptimizeConfig(iterations=150, views_per_step=2))
    start_noise: Weight = 0.5
    """std of the log-normal perturbation of the starting map (makes samples differ)"""

    @classmethod
    def from_dict(cls, values: dict) -> "ClassicConfig":
        """Config from a flat dict: OptimizeConfig keys plus this class's own."""
        return method_config_from_dict(cls, values)


def balanced_weight(data0: float, prior0: float, ratio: float) -> float:
    """Weight making ratio * data0 == weight * prior0 (prior0 ~ 0 falls back to a unit prior)."""
    return ratio * data0 / prior0 if prior0 > 1e-6 else ratio * data0


def classic_sample(problem: InverseProblem, method: str, init: Decomposition, cfg: ClassicConfig, seed: int,
                   progress: bool = True, checkpoint: Path | None = None) -> Decomposition:
    """One posterior sample of an optimisation-based prior, from the init decomposition (`checkpoint`:
    the fit's resume file)."""
    generator = torch.Generator().manual_seed(seed)
    prior = make_prior(method, init.env)
    log_env = init.env.clamp_min(1e-6).log() + cfg.start_noise * torch.randn(init.env.shape, generator=generator)
    materials = starting_materials(init)
    trace = Trace(info={"method": method, "seed": seed, "config": flat_config(cfg)})
    weight = 0.0
    if prior is not None:
        with torch.no_grad():
            env0 = log_env.exp()
            data0 = float(problem.data_loss(env0, materials, problem.train_ids, seed))
            weight = balanced_weight(data0, float(prior(env0)), PRIOR_WEIGHT_RATIO)
    trace.info["prior_weight"] = weight
    log_env, materials = fit(problem, log_env, materials, cfg.optimize, seed, trace, prior, weight, progress,
                             checkpoint)
    return Decomposition(log_env.exp(), materials, trace)
