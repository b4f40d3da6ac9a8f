"""Diffusion posterior sampling with an optimisable measurement operator (the paper's method, `dps`).

Reverse diffusion over the prior's image space x (tone-mapped env maps in [-1, 1]). At schedule
step t:
  eps     = roll^-1(eps_theta(roll(x_t), t))            fresh random azimuth roll (Eq. 15)
  x0_hat  = (x_t - sqrt(1 - abar_t) eps) / sqrt(abar_t), clamped to [-1, 1]
  L       = scale * f^-1(x0_hat)                        env map in scene radiance
  loss    = ||y - R(L, k, c)||                           over the foreground of a few training views
  g       = d loss / d x_t  (through renderer and network), rescaled to max|g| <= bound
  x_{t-1} = mu_theta(x_t, t) + sigma_t z  -  rho_t g
and one Adam step on albedo / roughness / metallic against the same loss (env detached: one
render and one backward pass give both gradients). After the last step the materials are refined
with the clean map fixed. A step with non-finite loss or gradient takes the plain reverse step
and skips the material update; a non-finite network output skips the step. All are counted in the trace.
Given a `checkpoint` file the reverse loop saves its state there every `checkpoint_every` steps and a
rerun continues from it (see dpi.solve.checkpoint); the refinement, short, is simply run again. The
file is deleted when the sample is done.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from dpi.materials import MaterialTextures
from dpi.prior.data import radiance_scale
from dpi.prior.diffusion import Diffusion, model_output_with_random_roll, model_timesteps, p_mean_variance
from dpi.prior.sample import Prior
from dpi.settings import settings_from_dict
from dpi.solve.checkpoint import LoopState, checkpoint_for, problem_identity
from dpi.solve.decomposition import Decomposition
from dpi.solve.init import starting_materials
from dpi.solve.optimize import OptimizeConfig, all_finite, fit
from dpi.solve.problem import InverseProblem
from dpi.solve.trace import Trace

RHO_SCHEDULES = ("linear", "step", "constant")
CHECKPOINT_EVERY = 10
"""reverse steps between two saves of the resume state (a save costs far less than one step)"""


@dataclass
class DPSConfig:
    """Settings of the `dps` method (defaults: the CPU preset)."""

    steps: int = 100
    """reverse-diffusion steps (respaced from the prior's 1000; the paper uses 1000)"""
    views_per_step: int = 1
    """training views rendered per diffusion step"""
    guidance_bound: float = 0.1
    """max-abs of the rendering-loss gradient after rescaling"""
    rho_start: float = 0.1
    """guidance weight during the first part of the steps"""
    rho_end: float = 1.0
    """guidance weight at the last step"""
    rho_schedule: str = "linear"
    """linear: rho_start, then linear to rho_end (outdoor); step: jump to rho_end (indoor); constant"""
    rho_switch: float = 0.5
    """fraction of steps run at rho_start"""
    lr_albedo: float = 2e-2
    lr_roughness: float = 1.5e-2
    lr_metallic: float = 1e-2
    refine_iterations: int = 200
    """Adam iterations on the materials with the final map fixed"""
    refine_views_per_step: int = 2
    radiance_scale: float | None = None
    """scene radiance per unit of the prior's normalised radiance (None: estimated from init)"""
    strip_frames: int = 8
    """x0_hat snapshots kept for the progress strip"""

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> "DPSConfig":
        """Config from a `method_params.dps` entry."""
        cfg = settings_from_dict(cls, values)
        if cfg.rho_schedule not in RHO_SCHEDULES:
            raise ValueError(f"rho_schedule must be one of {RHO_SCHEDULES}, got {cfg.rho_schedule!r}")
        return cfg


@dataclass
class DPSResult:
    """A dps decomposition and the x0_hat snapshots (prior space, (3, H, W) each) for the strip."""

    decomposition: Decomposition
    snapshots: list[torch.Tensor] = field(default_factory=list)


def rho_schedule(cfg: DPSConfig, n: int) -> np.ndarray:
    """Guidance weight per executed step (n steps, first executed = noisiest)."""
    first = int(round(cfg.rho_switch * n))
    rho = np.full(n, cfg.rho_start)
    if cfg.rho_schedule == "linear" and n > first:
        rho[first:] = np.linspace(cfg.rho_start, cfg.rho_end, n - first + 1)[1:]
    elif cfg.rho_schedule == "step":
        rho[first:] = cfg.rho_end
    return rho


def scale_to_bound(g: torch.Tensor, bound: float) -> torch.Tensor:
    """g rescaled so that max|g| <= bound (unchanged when already inside)."""
    peak = float(g.abs().max())
    return g * (bound / peak) if peak > bound else g


def material_optimizer(materials: MaterialTextures, cfg: DPSConfig) -> torch.optim.Adam:
    """Adam on albedo / roughness / metallic at their own learning rates: one step per reverse step."""
    return torch.optim.Adam([{"params": [materials.albedo], "lr": cfg.lr_albedo},
                             {"params": [materials.roughness], "lr": cfg.lr_roughness},
                             {"params": [materials.metallic], "lr": cfg.lr_metallic}])


def estimate_radiance_scale(init_env: torch.Tensor, prior: Prior) -> float:
    """Scene radiance per unit of the prior's normalised radiance: the init map's median luminance
    over the median the prior was trained with (the same normalisation as its training maps)."""
    return radiance_scale(init_env.permute(2, 0, 1), prior.median_target)


def prior_to_env(x0: torch.Tensor, prior: Prior, scale: float, height: int) -> torch.Tensor:
    """Prior image (1, 3, h, w) -> scene env map (H, 2H, 3) in radiance, resampled to `height`."""
    radiance = scale * prior.encoding.to_radiance(x0)
    if radiance.shape[-2] != height:
        radiance = torch.nn.functional.interpolate(radiance, size=(height, 2 * height), mode="bilinear",
                                                   align_corners=False)
    return radiance[0].permute(1, 2, 0)


def dps_sample(problem: InverseProblem, prior: Prior, init: Decomposition, cfg: DPSConfig, seed: int,
               progress: bool = True, checkpoint: Path | None = None,
               checkpoint_every: int = CHECKPOINT_EVERY) -> DPSResult:
    """One posterior sample: reverse diffusion guided by the renderer, joint material steps, refinement.
    With a `checkpoint` file the sample continues from the state a killed run of it left there."""
    generator = torch.Generator().manual_seed(seed)
    diffusion: Diffusion = prior.schedule(cfg.steps)
    scale = cfg.radiance_scale or estimate_radiance_scale(init.env, prior)
    height = problem.settings.env_height
    trace = Trace(info={"method": "dps", "seed": seed, "radiance_scale": scale, "family": prior.family,
                        "config": vars(cfg).copy()})
    materials = starting_materials(init)
    free = [t.requires_grad_(True) for _, t in materials.items()]
    optimizer = material_optimizer(materials, cfg)
    rho = rho_schedule(cfg, diffusion.num_timesteps)
    keep = set(np.linspace(0, diffusion.num_timesteps - 1, cfg.strip_frames).round().astype(int).tolist())
    x = torch.randn((1, 3, prior.height, 2 * prior.height), generator=generator)
    store = checkpoint_for(checkpoint, checkpoint_every, "dps", vars(cfg), seed, scale, problem_identity(problem),
                           init.env, dict(init.materials.items()), prior.family, prior.model.state_dict())
    state = store.resume({"x": x, **dict(materials.items())}, optimizer, generator, trace) if store else None
    start, snapshots = (state.step, state.snapshots) if state else (0, [])
    for n in tqdm(range(start, diffusion.num_timesteps), initial=start, total=diffusion.num_timesteps, desc="dps",
                  disable=not progress, mininterval=2.0):
        if store and store.due(n, start):
            store.save(LoopState.capture(n, {"x": x, **dict(materials.items())}, optimizer, generator, trace,
                                         snapshots))
        i = diffusion.num_timesteps - 1 - n
        t0 = trace.seconds
        x = x.detach().requires_grad_(True)
        t = torch.full((1,), i, dtype=torch.long)
        output = model_output_with_random_roll(prior.model, x, model_timesteps(diffusion, t), generator)
        p = p_mean_variance(diffusion, output, x, t)
        x0_hat = p["x0"].clamp(-1, 1)
        t_net = trace.seconds - t0
        if not (torch.isfinite(p["mean"]).all() and torch.isfinite(p["log_variance"]).all()):
            trace.skip(n, "non-finite network output")  # keep x_t: a NaN here would poison every later step
            continue
        views = problem.sample_views(cfg.views_per_step, generator)
        env = prior_to_env(x0_hat, prior, scale, height)
        loss = problem.residual_norm(env, materials, views, seed=seed * 7919 + n)
        optimizer.zero_grad()
        guided = bool(torch.isfinite(loss))
        if guided:
            loss.backward()
            guided = x.grad is not None and bool(torch.isfinite(x.grad).all()) and all_finite(free)
        with torch.no_grad():
            noise = torch.randn(x.shape, generator=generator) if i > 0 else torch.zeros_like(x)
            x_next = p["mean"] + torch.exp(0.5 * p["log_variance"]) * noise
            peak = float("nan")
            if guided:
                peak = float(x.grad.abs().max())
                x_next = x_next - rho[n] * scale_to_bound(x.grad, cfg.guidance_bound)
                optimizer.step()
                materials.clamp_()
            else:
                trace.nan_skips += 1
        if n in keep:
            snapshots.append(x0_hat.detach()[0])
        trace.record(step=n, t=int(diffusion.timestep_map[i]), loss=loss.item() if guided else None,
                     rho=float(rho[n]), guidance_max=peak, skipped=None if guided else "non-finite loss or gradient",
                     seconds=round(trace.seconds - t0, 4), seconds_network=round(t_net, 4))
        x = x_next
    final = x.detach().clamp(-1, 1)
    env = prior_to_env(final, prior, scale, height).detach()
    refine = OptimizeConfig(iterations=cfg.refine_iterations, views_per_step=cfg.refine_views_per_step,
                            optimize_env=False, lr_albedo=cfg.lr_albedo, lr_roughness=cfg.lr_roughness,
                            lr_metallic=cfg.lr_metallic)
    refine_trace = Trace()
    _, materials = fit(problem, env.clamp_min(1e-8).log(), materials.detached(), refine, seed + 1, refine_trace,
                       progress=progress)
    trace.info["refine"] = refine_trace.summary()
    trace.nan_skips += refine_trace.nan_skips
    if store:
        store.remove()
    return DPSResult(Decomposition(env, materials, trace), snapshots)
