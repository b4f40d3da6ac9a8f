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

from dataclasses import fields
from pathlib import Path
from typing import Any, Callable, TypeVar

import torch
from tqdm import tqdm

from dpi.io.settings import Count, Rate, Steps, check_keys, settings, settings_from_dict
from dpi.solve.checkpoint import LoopState, checkpoint_for, problem_identity
from dpi.solve.materials import MaterialRates, MaterialTextures
from dpi.solve.problem import InverseProblem
from dpi.solve.trace import Trace

LOG_ENV_RANGE = (-14.0, 14.0)  # radiance in about [1e-6, 1e6]
CHECKPOINT_EVERY = 25
"""Adam steps between two saves of a fit's resume state (a save costs far less than one render)"""


@settings
class OptimizeConfig(MaterialRates):
    """Adam settings of a joint env-map + materials fit (the textures' rates: MaterialRates)."""

    iterations: Steps = 400
    """number of Adam steps"""
    views_per_step: Count = 4
    """training views rendered per step (all views if larger than their number)"""
    lr_env: Rate = 3e-2
    """Adam learning rate of the env map's parameters (its log-radiance texels; dip: the network weights)"""

    @classmethod
    def from_dict(cls, values: dict) -> "OptimizeConfig":
        """Config from a config.yaml section."""
        return settings_from_dict(cls, values)


MethodConfig = TypeVar("MethodConfig")


def method_config_from_dict(cls: type[MethodConfig], values: dict[str, Any] | None) -> MethodConfig:
    """A method's config dataclass, whose `optimize` field is an OptimizeConfig, from one flat dict
    (a `method_params` entry): its own keys by name, the rest for OptimizeConfig; unknown keys, wrong
    types and out-of-range values are errors (dpi.io.settings)."""
    values = dict(values or {})
    own = {f.name for f in fields(cls)} - {"optimize"}
    check_keys(values, own | {f.name for f in fields(OptimizeConfig)}, f"{cls.__name__} setting")
    mine = {k: v for k, v in values.items() if k in own}
    defaults = vars(cls().optimize)  # the method's own defaults (e.g. 150 iterations), not OptimizeConfig's
    optimize = OptimizeConfig.from_dict({**defaults, **{k: v for k, v in values.items() if k not in own}})
    return cls(optimize=optimize, **mine)


def flat_config(cfg: Any) -> dict[str, Any]:
    """The flat dict of a method config (inverse of `method_config_from_dict`): its trace's, and its `method_params`
    entry as `dpi config` prints it."""
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


def fit_to_map(model: EnvModel, target: torch.Tensor, iterations: int, lr: float,
               penalty: Callable[[], torch.Tensor] | None = None) -> float | None:
    """Adam on the model's parameters so that its output matches a log-radiance map (no rendering), plus its
    `penalty` when given (a latent's prior); returns the final mean squared error (None without iterations)."""
    optimizer = torch.optim.Adam(model.parameters(), lr=lr)
    error = None
    for _ in range(iterations):
        mismatch = (model() - target).square().mean()
        loss = mismatch + penalty() if penalty else mismatch
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        error = mismatch.item()
    return error


def all_finite(tensors: list[torch.Tensor]) -> bool:
    """True when every gradient present is free of NaN/Inf."""
    return all(t.grad is None or bool(torch.isfinite(t.grad).all()) for t in tensors)


def fit(problem: InverseProblem, log_env: torch.Tensor, materials: MaterialTextures, cfg: OptimizeConfig,
        seed: int, trace: Trace, prior: PriorFn | None = None, prior_weight: float = 0.0,
        progress: bool = True, checkpoint: Path | None = None,
        checkpoint_every: int = CHECKPOINT_EVERY, free_env: bool = True) -> tuple[torch.Tensor, MaterialTextures]:
    """Minimise data loss (+ prior_weight * prior(env)) over free texels (the map's too unless `free_env` is
    False); returns the final log-env and materials."""
    return fit_env_model(problem, FreeEnvMap(log_env), materials, cfg, seed, trace, prior, prior_weight, progress,
                         checkpoint, checkpoint_every, free_env)


def fit_env_model(problem: InverseProblem, env_model: EnvModel, materials: MaterialTextures, cfg: OptimizeConfig,
                  seed: int, trace: Trace, prior: PriorFn | None = None, prior_weight: float = 0.0,
                  progress: bool = True, checkpoint: Path | None = None,
                  checkpoint_every: int = CHECKPOINT_EVERY, free_env: bool = True) -> tuple[torch.Tensor, MaterialTextures]:
    """Minimise data loss (+ prior_weight * prior(env)) over the env model's parameters (updated in
    place; fixed when `free_env` is False) and the materials; returns the final log-env and materials. With a
    `checkpoint` file the fit continues from the state a killed run of the same fit left there."""
    run = AdamFit(problem, env_model, materials, cfg, seed, trace, prior, prior_weight, free_env)
    run.resume(checkpoint, checkpoint_every)
    run.run(cfg.iterations, progress)
    return run.finish()


class AdamFit:
    """One Adam fit as an object: `run(until)` goes on from where the last call stopped, exactly as one
    uninterrupted loop would, and the fit's trace, materials and resume file stay at hand between calls (the
    init compares two fits before keeping one, dpi.solve.init)."""

    def __init__(self, problem: InverseProblem, env_model: EnvModel, materials: MaterialTextures,
                 cfg: OptimizeConfig, seed: int, trace: Trace, prior: PriorFn | None = None,
                 prior_weight: float = 0.0, free_env: bool = True):
        self.problem, self.env_model, self.cfg, self.seed, self.trace = problem, env_model, cfg, seed, trace
        self.prior, self.prior_weight = prior, prior_weight
        env_model.requires_grad_(free_env)
        self.materials = materials.detached()
        self.tensors = {**{f"env.{name}": t for name, t in env_model.state_dict().items()},
                        **dict(self.materials.items())}
        groups = [{"params": list(env_model.parameters()), "lr": cfg.lr_env}] if free_env else []
        for name, tensor in self.materials.items():
            tensor.requires_grad_(True)
            groups.append({"params": [tensor], "lr": cfg.rate(name)})
        self.free = [p for g in groups for p in g["params"]]
        self.optimizer = torch.optim.Adam(groups) if groups else None
        self.generator = torch.Generator().manual_seed(seed)
        self.step = 0
        self.store = None
        self.key = ("fit", vars(cfg), free_env, seed, prior_weight, problem_identity(problem),
                    {name: t.detach().clone() for name, t in self.tensors.items()})

    def resume(self, checkpoint: Path | None, every: int = CHECKPOINT_EVERY) -> None:
        """Save the loop's state to `checkpoint` from now on, continuing from the state a killed run of this
        fit (same config, seed, problem and start) left there."""
        self.store = checkpoint_for(checkpoint, every, *self.key)
        state = self.store.resume(self.tensors, self.optimizer, self.generator, self.trace) if self.store else None
        self.step = max(self.step, state.step if state else 0)

    def run(self, until: int, progress: bool = True) -> None:
        """Run the steps before `until`."""
        start, cfg, trace = self.step, self.cfg, self.trace
        for step in tqdm(range(start, until), initial=start, total=until, desc="optimise", disable=not progress,
                         mininterval=2.0):
            if self.store and self.store.due(step, start):
                self.store.save(LoopState.capture(step, self.tensors, self.optimizer, self.generator, trace))
            t0 = trace.seconds
            views = self.problem.sample_views(cfg.views_per_step, self.generator)
            env = self.env_model().exp()
            data = self.problem.data_loss(env, self.materials, views, seed=self.seed * 100_003 + step)
            use_prior = self.prior is not None and self.prior_weight > 0
            reg = self.prior(env) if use_prior else torch.zeros(())
            loss = data + self.prior_weight * reg
            if not torch.isfinite(loss):
                trace.skip(step, "non-finite loss")
                continue
            if self.optimizer is None:
                trace.record(step=step, loss=loss.item(), data=data.item(), seconds=trace.seconds - t0)
                continue
            self.optimizer.zero_grad()
            loss.backward()
            if not all_finite(self.free):
                trace.skip(step, "non-finite gradient")
                continue
            self.optimizer.step()
            self.env_model.constrain_()
            self.problem.constrain_(self.materials)
            trace.record(step=step, loss=loss.item(), data=data.item(), prior=reg.item(), views=views,
                         seconds=round(trace.seconds - t0, 4))
        self.step = max(start, until)

    def save(self) -> None:
        """Write where the loop stands to its resume file now (none: nothing), so a rerun starts from here."""
        if self.store:
            self.store.save(LoopState.capture(self.step, self.tensors, self.optimizer, self.generator, self.trace))

    def finish(self) -> tuple[torch.Tensor, MaterialTextures]:
        """The fit's log-env and materials; its resume file is removed (a later rerun is a new run)."""
        if self.store:
            self.store.remove()
        with torch.no_grad():
            return self.env_model().detach(), self.materials.detached()
