"""Joint Adam optimisation of a free environment map and material textures against the views.

The shared loop of the path-traced initialisation and of the optimisation-based priors
(`none`, `global_norm`, `smoothness`, `chromaticity`, `dip`). The map is an `EnvModel`: a module
whose forward pass gives log-radiance, either the free texels themselves (`FreeEnvMap`) or a
network that generates them (`dip`). Log-radiance makes a step change radiance relatively (HDR
maps span many orders of magnitude); materials are optimised directly and clamped to their valid
ranges after every step. A step whose loss or gradients are not finite is skipped and counted in
the trace. Given a `checkpoint` file the loop saves its state there every `checkpoint_every` steps
and a rerun continues from it (see dpi.solve.checkpoint); the file is deleted when the fit is done.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Callable, TypeVar

import torch
from tqdm import tqdm

from dpi.materials import MaterialRates, MaterialTextures
from dpi.settings import check_keys, check_values, settings_from_dict
from dpi.solve.checkpoint import LoopState, checkpoint_for, problem_identity
from dpi.solve.problem import InverseProblem
from dpi.solve.trace import Trace

LOG_ENV_RANGE = (-14.0, 14.0)  # radiance in about [1e-6, 1e6]
CHECKPOINT_EVERY = 25
"""Adam steps between two saves of a fit's resume state (a save costs far less than one render)"""


@dataclass
class OptimizeConfig(MaterialRates):
    """Adam settings of a joint env-map + materials fit (the textures' rates: MaterialRates)."""

    iterations: int = 400
    """number of Adam steps"""
    views_per_step: int = 4
    """training views rendered per step (all views if larger than their number)"""
    lr_env: float = 3e-2
    """Adam learning rate of the env map's parameters (its log-radiance texels; dip: the network weights)"""
    optimize_env: bool = True
    """False keeps the env map fixed (material refinement)"""
    optimize_materials: tuple[str, ...] = ("albedo", "roughness", "metallic")
    """which material textures are free"""

    @classmethod
    def from_dict(cls, values: dict) -> "OptimizeConfig":
        """Config from a config.yaml section (lists become tuples)."""
        values = dict(values)
        if isinstance(values.get("optimize_materials"), list):
            values["optimize_materials"] = tuple(values["optimize_materials"])
        return settings_from_dict(cls, values)


MethodConfig = TypeVar("MethodConfig")


def method_config_from_dict(cls: type[MethodConfig], values: dict[str, Any] | None) -> MethodConfig:
    """A method's config dataclass, whose `optimize` field is an OptimizeConfig, from one flat dict
    (a `method_params` entry): its own keys by name, the rest for OptimizeConfig; unknown keys, wrong
    types and out-of-range values are errors (dpi.settings)."""
    values = dict(values or {})
    own = {f.name for f in fields(cls)} - {"optimize"}
    check_keys(values, own | {f.name for f in fields(OptimizeConfig)}, f"{cls.__name__} setting")
    mine = {k: v for k, v in values.items() if k in own}
    check_values(cls, mine)
    defaults = vars(cls().optimize)  # the method's own defaults (e.g. 150 iterations), not OptimizeConfig's
    optimize = OptimizeConfig.from_dict({**defaults, **{k: v for k, v in values.items() if k not in own}})
    return cls(optimize=optimize, **mine)


def flat_config(cfg: Any) -> dict[str, Any]:
    """The flat dict of a method config (inverse of `method_config_from_dict`), for its trace."""
    return {**vars(cfg.optimize), **{k: v for k, v in vars(cfg).items() if k != "optimize"}}


PriorFn = Callable[[torch.Tensor], torch.Tensor]


class EnvModel(torch.nn.Module):
    """A parametrisation of the env map: `forward()` gives its log-radiance (H, 2H, 3)."""

    def constrain_(self) -> None:
        """Project the parameters back into their valid set after an optimiser step (default: none)."""


class FreeEnvMap(EnvModel):
    """The map's log-radiance texels as free parameters, clamped to LOG_ENV_RANGE after each step."""

    def __init__(self, log_env: torch.Tensor):
        super().__init__()
        self.log_env = torch.nn.Parameter(log_env.detach().clone())

    def forward(self) -> torch.Tensor:
        """The log-radiance map itself."""
        return self.log_env

    @torch.no_grad()
    def constrain_(self) -> None:
        """Keep radiance inside about [1e-6, 1e6]."""
        self.log_env.clamp_(*LOG_ENV_RANGE)


def all_finite(tensors: list[torch.Tensor]) -> bool:
    """True when every gradient present is free of NaN/Inf."""
    return all(t.grad is None or bool(torch.isfinite(t.grad).all()) for t in tensors)


def fit(problem: InverseProblem, log_env: torch.Tensor, materials: MaterialTextures, cfg: OptimizeConfig,
        seed: int, trace: Trace, prior: PriorFn | None = None, prior_weight: float = 0.0,
        progress: bool = True, checkpoint: Path | None = None,
        checkpoint_every: int = CHECKPOINT_EVERY) -> tuple[torch.Tensor, MaterialTextures]:
    """Minimise data loss (+ prior_weight * prior(env)) over free texels; returns the final log-env and materials."""
    return fit_env_model(problem, FreeEnvMap(log_env), materials, cfg, seed, trace, prior, prior_weight, progress,
                         checkpoint, checkpoint_every)


def fit_env_model(problem: InverseProblem, env_model: EnvModel, materials: MaterialTextures, cfg: OptimizeConfig,
                  seed: int, trace: Trace, prior: PriorFn | None = None, prior_weight: float = 0.0,
                  progress: bool = True, checkpoint: Path | None = None,
                  checkpoint_every: int = CHECKPOINT_EVERY) -> tuple[torch.Tensor, MaterialTextures]:
    """Minimise data loss (+ prior_weight * prior(env)) over the env model's parameters (updated in
    place) and the materials; returns the final log-env and materials. With a `checkpoint` file the
    fit continues from the state a killed run of the same fit left there."""
    env_model.requires_grad_(cfg.optimize_env)
    materials = materials.detached()
    tensors = {**{f"env.{name}": t for name, t in env_model.state_dict().items()}, **dict(materials.items())}
    groups = [{"params": list(env_model.parameters()), "lr": cfg.lr_env}] if cfg.optimize_env else []
    for name, tensor in materials.items():
        if name in cfg.optimize_materials:
            tensor.requires_grad_(True)
            groups.append({"params": [tensor], "lr": cfg.rate(name)})
    free = [p for g in groups for p in g["params"]]
    optimizer = torch.optim.Adam(groups) if groups else None
    generator = torch.Generator().manual_seed(seed)
    store = checkpoint_for(checkpoint, checkpoint_every, "fit", vars(cfg), seed, prior_weight,
                           problem_identity(problem), tensors)
    state = store.resume(tensors, optimizer, generator, trace) if store else None
    start = state.step if state else 0
    for step in tqdm(range(start, cfg.iterations), initial=start, total=cfg.iterations, desc="optimise",
                     disable=not progress, mininterval=2.0):
        if store and store.due(step, start):
            store.save(LoopState.capture(step, tensors, optimizer, generator, trace))
        t0 = trace.seconds
        views = problem.sample_views(cfg.views_per_step, generator)
        env = env_model().exp()
        data = problem.data_loss(env, materials, views, seed=seed * 100_003 + step)
        reg = prior(env) if prior is not None and prior_weight > 0 else torch.zeros(())
        loss = data + prior_weight * reg
        if not torch.isfinite(loss):
            trace.skip(step, "non-finite loss")
            continue
        if optimizer is None:
            trace.record(step=step, loss=loss.item(), data=data.item(), seconds=trace.seconds - t0)
            continue
        optimizer.zero_grad()
        loss.backward()
        if not all_finite(free):
            trace.skip(step, "non-finite gradient")
            continue
        optimizer.step()
        env_model.constrain_()
        materials.clamp_()
        trace.record(step=step, loss=loss.item(), data=data.item(), prior=reg.item(), views=views,
                     seconds=round(trace.seconds - t0, 4))
    if store:
        store.remove()
    with torch.no_grad():
        return env_model().detach(), materials.detached()
