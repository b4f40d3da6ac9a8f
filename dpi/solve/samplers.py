"""One reverse-diffusion step of `dps` per sampler; `dpi.solve.dps` runs the loop around them.

A step function takes the run (what is fixed for one sample: problem, prior, schedule, config)
and the loop state (x_t, materials, log-exposure, Adam, random stream), advances the state by
one schedule step, and returns the step's record for the trace (`skipped` says why a step did
not update; `nan_inner` counts skipped inner updates; `seconds_*` time its parts).

- `paper` (Lyu et al. 2023; LinjieLyu/DPI): eps from the randomly rolled x_t (Eq. 15), x0_hat by
  Tweedie, clamped; the gradient of ||y - R(L(x0_hat), k)|| w.r.t. x_t through renderer and network,
  bounded in max-abs, subtracted with weight rho_t from the ancestral step; one Adam step on the
  materials from the same render. Tuned for 1000 steps.
- `proximal` (the DiffPIR / DDS family: Zhu et al. 2023, Chung et al. 2024): the data term acts on
  x0, not x_t, and needs no backward pass through the network. `inner_steps` Adam steps on the map's
  log radiance l (prior resolution) and the materials against
  ||y - c R(exp(l + s), k)||^2 / ||y||^2  +  prox_weight abar_t / (1 - abar_t) ||z(l) - x0_hat||^2
  with z(l) the map in prior space, over `views_per_step` views per inner step (one render and one
  backward feed both). The renderer is linear in the map, so the global exposure is solved exactly:
  c is the least-squares scale of each render, and s += ln c. l starts from x0_hat at the first step
  and from the previous step's l after that (the data fit accumulates). Then re-noise: x_{t-1} = sqrt(abar_{t-1}) z + sqrt(1 - abar_{t-1})
  (sqrt(1 - zeta) eps_hat + sqrt(zeta) eps) with eps_hat recomputed from z, so samples stay diverse.
  The proximal weight grows as the noise falls (DiffPIR's rho_t ~ 1 / sigma_t^2), so late steps
  keep what the data put into x_t early. The materials move only after `material_start` of the
  steps: while x0_hat is still a blur, free albedo steps would absorb the map's errors.
  With a sun (`sun`, dpi.solve.sun) the map is the prior's sky plus a parametric sun splatted at the
  problem's resolution; its position and irradiance are fitted with the rest, and a prior on its
  share of the map's energy settles what the views cannot (a diffuse object barely tells a sun from
  a bright patch of sky around it).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable

import numpy as np
import torch

from dpi.images import luminance
from dpi.materials import MaterialTextures
from dpi.prior.diffusion import Diffusion, model_output_with_random_roll, model_timesteps, p_mean_variance
from dpi.prior.sample import Prior
from dpi.solve.optimize import all_finite
from dpi.solve.problem import InverseProblem
from dpi.solve.sun import share_penalty, sun_env, wrap_uv_

if TYPE_CHECKING:
    from dpi.solve.dps import DPSConfig


MAX_EXPOSURE_STEP = 3.0
"""proximal: largest change of the log-exposure in one data update"""
DARK_FLOOR = 1e-6
"""proximal: radiance floor (times the prior's median) before the logarithm (the paper's curve reaches 0)"""


@dataclass
class DPSRun:
    """What stays fixed during one posterior sample."""

    problem: InverseProblem
    prior: Prior
    cfg: "DPSConfig"
    diffusion: Diffusion
    seed: int
    scale: float
    """scene radiance per unit of the prior's normalised radiance (times exp(log-exposure))"""
    rho: np.ndarray
    """paper: guidance weight per executed step"""
    data_norm: float
    """proximal: mean squared foreground radiance of the training views (makes the data term relative)"""
    first_index: int
    """schedule index of the first executed step (the last index, or lower when starting from the noised init)"""

    @property
    def num_steps(self) -> int:
        """Executed reverse steps."""
        return self.first_index + 1

    def index(self, n: int) -> int:
        """Schedule index of executed step n (the first executed step is the noisiest)."""
        return self.first_index - n

    sun: bool = False
    """the map has a parametric sun (dpi.solve.sun) next to the prior's sky"""

    def env(self, radiance: torch.Tensor, state: "DPSState") -> torch.Tensor:
        """Prior-resolution normalised radiance (1, 3, h, 2h) -> scene env map (H, 2H, 3) at the problem's
        height, times the state's exposure, plus its sun (splatted at the problem's height, so it stays a
        point of light where the prior's resolution would blur it)."""
        height = self.problem.settings.env_height
        env = self.scale * torch.exp(state.log_exposure) * resample_env(radiance, height)
        return env + sun_env(state.sun_uv, self.sun_irradiance(state), height) if self.sun else env

    def sun_irradiance(self, state: "DPSState") -> torch.Tensor:
        """(3,) the state's sun in scene radiance units (its log irradiance is in the prior's, times the exposure)."""
        return self.scale * torch.exp(state.log_exposure + state.sun_log)

    def views(self, generator: torch.Generator) -> list[int]:
        """Training views of one data term."""
        return self.problem.sample_views(self.cfg.views_per_step, generator)

    def render_seed(self, n: int, k: int = 0) -> int:
        """Mitsuba seed of inner update k of step n (a continued run renders what an uninterrupted one would)."""
        return self.seed * 7919 + n * 31 + k


@dataclass
class DPSState:
    """What the reverse loop carries from step to step (saved in resume files)."""

    x: torch.Tensor
    """x_t (1, 3, h, 2h) in prior space"""
    materials: MaterialTextures
    log_exposure: torch.Tensor
    """global log-exposure of the map (scalar): absorbs the light/albedo scale ambiguity; proximal: fitted
    in closed form at every data update"""
    log_map: torch.Tensor
    """proximal: the map's normalised log radiance (1, 3, h, 2h) during the inner updates"""
    sun_uv: torch.Tensor
    """(2,) map coordinates of the sun (used when the run has one)"""
    sun_log: torch.Tensor
    """(3,) log irradiance of the sun per channel, in the prior's normalised units (times the exposure)"""
    optimizer: torch.optim.Adam
    generator: torch.Generator
    snapshots: list[torch.Tensor] = field(default_factory=list)
    """x0_hat at a few steps, for the progress strip"""

    def tensors(self) -> dict[str, torch.Tensor]:
        """The loop's variables by name (for resume files)."""
        return {"x": self.x, **dict(self.materials.items()), "log_exposure": self.log_exposure,
                "log_map": self.log_map, "sun_uv": self.sun_uv, "sun_log": self.sun_log}


def resample_env(radiance: torch.Tensor, height: int) -> torch.Tensor:
    """(1, 3, h, 2h) radiance -> (height, 2 height, 3), bilinear (a 2x2 average when halving)."""
    if radiance.shape[-2] != height:
        radiance = torch.nn.functional.interpolate(radiance, size=(height, 2 * height), mode="bilinear",
                                                   align_corners=False)
    return radiance[0].permute(1, 2, 0)


def rho_schedule(cfg: "DPSConfig", n: int) -> np.ndarray:
    """paper: guidance weight per executed step (n steps, first executed = noisiest)."""
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


class Laps:
    """Wall time of a step's parts: `lap(name)` adds the time since the previous lap to `name`."""

    def __init__(self) -> None:
        self.start = self.clock = time.perf_counter()
        self.seconds: dict[str, float] = {}

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.seconds[name] = self.seconds.get(name, 0.0) + now - self.clock
        self.clock = now

    def record(self) -> dict[str, float]:
        """seconds (whole step) and seconds_<part>, rounded."""
        return {"seconds": round(time.perf_counter() - self.start, 4),
                **{f"seconds_{k}": round(v, 4) for k, v in self.seconds.items()}}


def network_step(run: DPSRun, x: torch.Tensor, i: int, generator: torch.Generator) -> dict[str, torch.Tensor]:
    """p_mean_variance of the randomly rolled network output at schedule index i (x0 clamped to [-1, 1])."""
    t = torch.full((1,), i, dtype=torch.long)
    output = model_output_with_random_roll(run.prior.model, x, model_timesteps(run.diffusion, t), generator)
    return p_mean_variance(run.diffusion, output, x, t)


def finite(*tensors: torch.Tensor) -> bool:
    """True when every tensor is free of NaN/Inf."""
    return all(bool(torch.isfinite(t).all()) for t in tensors)


def paper_step(run: DPSRun, state: DPSState, n: int) -> dict[str, Any]:
    """The paper's guided ancestral step (gradient through renderer and network, bounded, times rho_t)."""
    laps, i, gen = Laps(), run.index(n), state.generator
    x = state.x.detach().requires_grad_(True)
    p = network_step(run, x, i, gen)
    laps.lap("network")
    record = {"step": n, "t": int(run.diffusion.timestep_map[i]), "rho": float(run.rho[n])}
    if not finite(p["mean"], p["log_variance"]):
        return {**record, "skipped": "non-finite network output", **laps.record()}  # keep x_t
    state.snapshots.append(p["x0"].detach()[0])
    env = run.env(run.prior.encoding.to_radiance(p["x0"]), state)
    env_leaf = env.detach().requires_grad_(True)
    loss = run.problem.residual_norm(env_leaf, state.materials, run.views(gen), seed=run.render_seed(n))
    state.optimizer.zero_grad()
    guided = finite(loss)
    if guided:
        loss.backward()
        laps.lap("render")
        env.backward(env_leaf.grad)
        laps.lap("network_backward")
        guided = x.grad is not None and finite(x.grad) and all_finite(list(dict(state.materials.items()).values()))
    with torch.no_grad():
        noise = torch.randn(x.shape, generator=gen) if i > 0 else torch.zeros_like(x)
        x_next = p["mean"] + torch.exp(0.5 * p["log_variance"]) * noise
        if guided:
            record["guidance_max"] = float(x.grad.abs().max())
            x_next = x_next - run.rho[n] * scale_to_bound(x.grad, run.cfg.guidance_bound)
            state.optimizer.step()
            state.materials.clamp_()
    state.x = x_next
    if not guided:
        record["skipped"] = "non-finite loss or gradient"
    return {**record, "loss": loss.item() if guided else None, **laps.record()}


def rendered_views(run: DPSRun, env: torch.Tensor, materials: MaterialTextures, views: list[int],
                   seed: int) -> list[torch.Tensor]:
    """The data term's renders of `views` (each with its own seed, at the sampler's spp)."""
    return [run.problem.render(env, materials, v, seed * 1009 + j, run.cfg.spp) for j, v in enumerate(views)]


def exposure_fit(run: DPSRun, renders: list[torch.Tensor], views: list[int]) -> float:
    """The least-squares global scale c of the renders against the images over their foreground: the
    renderer is linear in the map, so this is the exposure's exact optimum for the current map."""
    num = den = 0.0
    for rendered, v in zip(renders, views):
        mask = run.problem.masks[v].reshape(*rendered.shape[:-1], 1).to(rendered.dtype)
        num += float((mask * rendered * run.problem.images[v]).sum())
        den += float((mask * rendered.square()).sum())
    c = num / den if den > 0 and math.isfinite(num / den) and num > 0 else 1.0
    return min(max(c, math.exp(-MAX_EXPOSURE_STEP)), math.exp(MAX_EXPOSURE_STEP))


def recentre_(log_map: torch.Tensor, median_target: float) -> float:
    """Shift the map's log radiance so its median luminance is the prior's (in place); returns the shift
    for the exposure to take over. Map level and exposure are one degree of freedom: without this the
    level drifts and the encoded map saturates."""
    with torch.no_grad():
        shift = float(torch.log(luminance(torch.exp(log_map[0]).permute(1, 2, 0)).median() / median_target))
        log_map -= shift
    return shift


def normalized_step_(log_map: torch.Tensor, lr: float) -> None:
    """A gradient step on the map scaled to RMS `lr` over the texels (each texel's step clipped to 3 lr),
    taken in place and the gradient cleared: texels the data barely sees barely move, unlike under Adam."""
    with torch.no_grad():
        g = log_map.grad
        step = lr * g / g.square().mean().sqrt().clamp_min(1e-30)
        log_map -= step.clamp(-3 * lr, 3 * lr)
    log_map.grad = None


def relative_data_loss(run: DPSRun, renders: list[torch.Tensor], views: list[int], c: float) -> torch.Tensor:
    """Mean foreground loss of the renders times c over the mean squared foreground radiance: ~1 / SNR."""
    return sum(run.problem.view_loss(c * r, v) for r, v in zip(renders, views)) / (len(views) * run.data_norm)


def proximal_step(run: DPSRun, state: DPSState, n: int) -> dict[str, Any]:
    """x0_hat, `inner_steps` joint data updates of (map, materials, exposure) near it, stochastic re-noising."""
    cfg, laps, i, gen = run.cfg, Laps(), run.index(n), state.generator
    encoding = run.prior.encoding
    with torch.no_grad():
        p = network_step(run, state.x, i, gen)
    laps.lap("network")
    record: dict[str, Any] = {"step": n, "t": int(run.diffusion.timestep_map[i])}
    if not finite(p["x0"]):
        return {**record, "skipped": "non-finite network output", **laps.record()}  # keep x_t
    x0_hat = p["x0"]
    state.snapshots.append(x0_hat[0])
    abar = float(run.diffusion.alphas_cumprod[i])
    abar_prev = float(run.diffusion.alphas_cumprod_prev[i])
    prox_weight = cfg.prox_weight * abar / (1.0 - abar)
    materials_move = n >= cfg.material_start * run.num_steps
    if n == 0 or not cfg.warm_start:
        floor = DARK_FLOOR * run.prior.median_target
        with torch.no_grad():
            state.log_map.copy_(torch.log(encoding.to_radiance(x0_hat).clamp_min(floor)))
    losses, skipped = [], 0
    for k in range(cfg.inner_steps):
        views = run.views(gen)
        env = run.env(torch.exp(state.log_map), state)
        renders = rendered_views(run, env, state.materials, views, run.render_seed(n, k))
        c = exposure_fit(run, [r.detach() for r in renders], views)
        state.log_exposure += math.log(c)
        data = relative_data_loss(run, renders, views, c)
        prox = (encoding.to_prior(torch.exp(state.log_map)) - x0_hat).square().mean()
        loss = data + prox_weight * prox
        if run.sun:
            loss = loss + cfg.sun_prior_weight * share_penalty(run.sun_irradiance(state), env, cfg.sun_share)
        state.optimizer.zero_grad()
        if not finite(loss):
            skipped += 1
            continue
        loss.backward()
        if not all_finite([state.log_map, state.sun_uv, state.sun_log, *dict(state.materials.items()).values()]):
            skipped += 1
            continue
        if not materials_move:
            for _, t in state.materials.items():
                t.grad = None
        if cfg.map_update == "normalized":
            normalized_step_(state.log_map, cfg.lr_map)
        state.optimizer.step()
        state.materials.clamp_()
        wrap_uv_(state.sun_uv)
        shift = recentre_(state.log_map, run.prior.median_target)
        state.log_exposure += shift
        with torch.no_grad():
            state.sun_log -= shift
        losses.append(float(data.detach()))
    laps.lap("render")
    with torch.no_grad():
        z = encoding.to_prior(torch.exp(state.log_map))
        eps_hat = (state.x - abar ** 0.5 * z) / (1.0 - abar) ** 0.5
        noise = torch.randn(z.shape, generator=gen)
        mixed = (1.0 - cfg.noise_mix) ** 0.5 * eps_hat + cfg.noise_mix ** 0.5 * noise
        state.x = abar_prev ** 0.5 * z + (1.0 - abar_prev) ** 0.5 * mixed
    return {**record, "loss": losses[-1] if losses else None, "prox": float(prox.detach()), "prox_weight": prox_weight,
            "log_exposure": float(state.log_exposure), "nan_inner": skipped,
            **({"skipped": "non-finite loss or gradient"} if not losses else {}), **laps.record()}


StepFunction = Callable[[DPSRun, DPSState, int], dict[str, Any]]
SAMPLERS: dict[str, StepFunction] = {"proximal": proximal_step, "paper": paper_step}
"""dps's samplers by name (the `sampler` setting); the first is the default"""
