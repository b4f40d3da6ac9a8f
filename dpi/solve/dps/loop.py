"""One `dps` posterior sample: the reverse-diffusion loop around a sampler's step, then the refinement.

`posterior_steps` is the loop: a generator that runs one sampler step per schedule step and yields
its record, like guided-diffusion's `p_sample_loop_progressive`; `dps_phases` consumes it for the
trace, the progress bar and the resume file and yields the whole sample phase by phase (its maps as they form, for
notebook/scripts/balance_trace.py), `dps_sample` runs that to its end, and benchmarks/timing/dps_step.py times the loop.
A step with a non-finite network output, loss or gradient does not update (it is counted in the trace).
Given a `checkpoint` file the loop saves its state there every `checkpoint_every` steps and a
rerun continues from it (see dpi.solve.checkpoint); the refinement, short, is simply run again.
The file is deleted when the sample is done.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import torch
from tqdm import tqdm

from dpi.light.sunlight import SUN_RADIUS_DEG
from dpi.prior.diffusion import q_sample
from dpi.prior.sample import Prior
from dpi.solve.checkpoint import LoopState, checkpoint_for, problem_identity
from dpi.solve.decomposition import Decomposition
from dpi.solve.dps.config import SAMPLERS, DPSConfig
from dpi.solve.dps.refine import refine
from dpi.solve.dps.start import glossy_start, polish_height, sample_start_materials, settings_for_init
from dpi.solve.dps.state import DPSRun, DPSState
from dpi.solve.dps.sun_choice import LR_SUN, LR_SUN_UV, wants_sun
from dpi.solve.dps.sun_size import views_sun_radius
from dpi.solve.materials import MaterialRates, MaterialTextures
from dpi.solve.prior_space import env_to_prior, estimate_radiance_scale
from dpi.solve.problem import InverseProblem
from dpi.solve.sun_model import extract_sun, sun_summary
from dpi.solve.trace import Trace
from dpi.solve.transport import LightTransport

CHECKPOINT_EVERY = 10
"""reverse steps between two saves of the resume state (a save costs far less than one step)"""
ADAM_BETAS = (0.9, 0.99)
"""the data loss falls by orders of magnitude during a sample: a short second-moment memory keeps
Adam's steps from stalling on the large gradients of the first steps"""


@dataclass
class DPSResult:
    """A dps decomposition and the x0_hat snapshots (prior space, (3, H, W) each) for the strip."""

    decomposition: Decomposition
    snapshots: list[torch.Tensor] = field(default_factory=list)


def state_optimizer(materials: MaterialTextures, rates: MaterialRates, lr_map: float, log_map: torch.Tensor,
                    sun_uv: torch.Tensor, sun_log: torch.Tensor) -> torch.optim.Adam:
    """Adam on albedo / roughness / metallic, the map's log radiance and the sun, each at its own rate
    (a sampler's step updates those whose gradient it computed; the materials' groups keep their rate as `base_lr`,
    which a sampler may scale)."""
    return torch.optim.Adam([*({"params": [t], "lr": rates.rate(name), "base_lr": rates.rate(name), "material": True}
                               for name, t in materials.items()),
                             {"params": [log_map], "lr": lr_map},
                             {"params": [sun_uv], "lr": LR_SUN_UV},
                             {"params": [sun_log], "lr": LR_SUN}], betas=ADAM_BETAS)


def data_norm(problem: InverseProblem) -> float:
    """Mean squared foreground radiance over the training views (the relative data term's unit)."""
    values = [problem.images[i][problem.masks[i]].square().mean() for i in problem.train_ids]
    return max(float(torch.stack(values).mean()), 1e-30)


def start_run(problem: InverseProblem, prior: Prior, init: Decomposition, cfg: DPSConfig,
              seed: int, radiance_scale: float | None = None) -> tuple[DPSRun, DPSState]:
    """The fixed part of one sample and its loop state at its first step (its materials: dpi.solve.dps.start):
    x_T ~ N(0, I), or the init map noised to the sampler's start_noise."""
    adapted = settings_for_init(cfg, init, prior.height)
    if adapted is not cfg:
        print(f"glossy init: its samples' rule applies (dpi.solve.dps.start: proximal inner_steps "
              f"{adapted.proximal.inner_steps}, map_solve {adapted.proximal.map_solve}; refine iterations "
              f"{adapted.refine.iterations}, views_per_step {adapted.refine.views_per_step}, lr_texels "
              f"{adapted.refine.lr_texels:g})", flush=True)
    cfg = adapted
    sampler = cfg.sampler_settings
    generator = torch.Generator().manual_seed(seed)
    diffusion = prior.schedule(cfg.steps)
    scale = radiance_scale or estimate_radiance_scale(init.env, prior)
    first = int(round(sampler.start_noise * (diffusion.num_timesteps - 1)))
    sun = extract_sun(init.env)
    has_sun = wants_sun(cfg.sun, sampler.models_sun, prior.family, glossy_start(init), sun)
    run = DPSRun(problem, prior, sampler, cfg, diffusion, seed, scale, data_norm(problem), first,
                 cfg.sun if has_sun else None, init)
    materials = sample_start_materials(init)
    for _, t in materials.items():
        t.requires_grad_(True)
    shape = (1, 3, prior.height, 2 * prior.height)
    log_map = torch.zeros(shape, requires_grad=True)
    sun_uv = sun.uv.clone().requires_grad_(True)
    sun_log = torch.log(sun.irradiance.clamp_min(1e-12 * scale) / scale).requires_grad_(True)
    x = torch.randn(shape, generator=generator)
    if first < diffusion.num_timesteps - 1:
        start = env_to_prior(sun.sky if has_sun else init.env, prior, scale)
        x = q_sample(diffusion, start, torch.tensor([first]), x)
    lr_map = getattr(sampler, "lr_map", 0.0)  # samplers without a log map never step it
    state = DPSState(x, materials, torch.zeros(()), log_map, sun_uv, sun_log,
                     state_optimizer(materials, cfg, lr_map, log_map, sun_uv, sun_log), generator)
    return run, state


def posterior_steps(run: DPSRun, state: DPSState, start: int = 0) -> Iterator[dict[str, Any]]:
    """Run the sampler's reverse steps start .. end on `state`, yielding each step's record."""
    step = SAMPLERS[run.cfg.sampler].step
    for n in range(start, run.num_steps):
        yield step(run, state, n)


MAP_PHASES = ("x0_hat", "solved", "loop", "kept", "refined")
"""the maps `dps_phases` yields, in the order a sample passes them: per step `x0_hat` (the network's guess) and
`solved` (the step's map after its data updates), then once each `loop` (the loop's map), `kept` (after
keep_what_the_views_see) and `refined` (the written map)"""


STRIP_FRAMES = 8
"""x0_hat snapshots kept for the progress strip"""


def strip_frames(snapshots: list[torch.Tensor], count: int) -> list[torch.Tensor]:
    """`count` evenly spaced snapshots (all when fewer)."""
    if len(snapshots) <= count:
        return snapshots
    keep = np.linspace(0, len(snapshots) - 1, count).round().astype(int)
    return [snapshots[k] for k in keep]


LOBE_SR = (0.05, 0.25)
"""solid angle (sr) of the map a pixel of the object sees (a texel's over the pixel's largest texel weight over its
total, the median over the texels the views see): up to the first, a mirror's, whose views pin down what they
reflect; from the second on, a rough object's wide lobe, whose sample stays as drawn (on a transport grid as coarse
as a rough lobe nothing is pinned)"""


def seen_weight(weights: torch.Tensor, height: int) -> torch.Tensor:
    """(height, 2 height) in [0, 1): how firmly the training views pin each texel, from each recorded pixel's weight on
    each texel (P, N): the views' weight on the texel over the median seen texel's (as s / (s + median)), times how
    mirror-like the views are (1 at a lobe of LOBE_SR[0] or less, 0 from LOBE_SR[1])."""
    seen = weights.sum(0)
    if not bool((seen > 0).any()):
        return torch.zeros(height, 2 * height)
    pixel_sharpness = weights.amax(dim=1, keepdim=True) / weights.sum(dim=1, keepdim=True).clamp_min(1e-30)
    sharpness = ((pixel_sharpness * weights).sum(0) / seen.clamp_min(1e-30))[seen > 0].median()
    lobe = 4 * math.pi / weights.shape[1] / sharpness
    mirror = ((LOBE_SR[1] - lobe) / (LOBE_SR[1] - LOBE_SR[0])).clamp(0, 1)
    median = seen[seen > 0].median()
    return (mirror * seen / (seen + median)).reshape(height, 2 * height)


def transport_weights(transport: LightTransport) -> torch.Tensor:
    """(P, N) each recorded pixel's weight on each texel at the materials' own roughness (slope and offset, halves'
    mean, channels summed)."""
    return transport.mean.abs().sum(dim=(0, 1))


def keep_what_the_views_see(env: torch.Tensor, init_env: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """The sample's map (H, 2H, 3) moved towards the init's in log radiance by `weight` (h, 2h, bilinearly resampled):
    what the views pin down stays as the init fitted it (its detail too), the prior's sample fills the rest, brought
    to the init's level where both hold (unchanged where nothing is pinned)."""
    if not bool((weight > 0).any()):
        return env
    w = torch.nn.functional.interpolate(weight[None, None].float(), size=env.shape[:2], mode="bilinear",
                                        align_corners=False)[0, 0, :, :, None]
    a, b = init_env.clamp_min(1e-8).log(), env.clamp_min(1e-8).log()
    shift = ((a - b) * w).sum(dim=(0, 1)) / w.sum().clamp_min(1e-8)
    return torch.exp(w * a + (1 - w) * (b + shift))


def dps_phases(problem: InverseProblem, prior: Prior, init: Decomposition, cfg: DPSConfig, seed: int,
               progress: bool = True, checkpoint: Path | None = None, checkpoint_every: int = CHECKPOINT_EVERY,
               radiance_scale: float | None = None) -> Iterator[dict[str, Any]]:
    """One posterior sample phase by phase (reverse diffusion guided by the views, joint material steps, refinement),
    as guided-diffusion's progressive loop: per reverse step {"phase": "step", "record": its trace record, "x0_hat",
    "solved"}, then {"phase": "loop"}, {"phase": "kept"} and {"phase": "refined", "result": the DPSResult}, each with
    its map (H, 2H, 3) under `env` (MAP_PHASES name them). With a `checkpoint` file the sample continues from the state
    a killed run of it left there. `radiance_scale`: the problem's radiance per unit of the prior's (None: estimated
    from the init's map)."""
    run, state = start_run(problem, prior, init, cfg, seed, radiance_scale)
    settings = asdict(cfg)
    trace = Trace(info={"method": "dps", "sampler": cfg.sampler, "seed": seed, "radiance_scale": run.scale,
                        "family": prior.family, "config": settings})
    store = checkpoint_for(checkpoint, checkpoint_every, "dps", settings, seed, run.scale, problem_identity(problem),
                           init.env, dict(init.materials.items()), prior.family, prior.model.state_dict())
    saved = store.resume(state.tensors(), state.optimizer, state.generator, trace) if store else None
    start = saved.step if saved else 0
    if saved:
        state.snapshots = list(saved.snapshots)
    refreshes = 0
    bar = tqdm(total=run.num_steps, initial=start, desc=f"dps {cfg.sampler}", disable=not progress,
               mininterval=2.0)
    for record in posterior_steps(run, state, start):
        trace.nan_skips += int("skipped" in record) + record.pop("nan_inner", 0)
        refreshes += int(record.get("refresh", False))
        trace.record(**record)
        bar.update(1)
        with torch.no_grad():
            guess = prior.encoding.to_radiance(state.snapshots[-1][None])[0].permute(1, 2, 0) \
                if state.snapshots else None
            solved = torch.exp(state.log_map[0]).permute(1, 2, 0).clone()
        yield {"phase": "step", "record": record, "x0_hat": guess, "solved": solved}
        n = record["step"] + 1
        if store and n < run.num_steps and store.due(n, start):
            store.save(LoopState.capture(n, state.tensors(), state.optimizer, state.generator, trace,
                                         state.snapshots))
    bar.close()
    transport = state.extra.get("transport")
    with torch.no_grad():
        sky, sun_irradiance, merged = run.written_sky(prior.encoding.to_radiance(state.x.clamp(-1, 1)), state)
        radius, radius_losses = (views_sun_radius(problem, lambda r: run.with_sun(sky, sun_irradiance, state, r),
                                                  state.materials, seed + 2, prior.height)
                                 if run.sun else (SUN_RADIUS_DEG, None))
        env = run.with_sun(sky, sun_irradiance, state, radius)
    trace.info["log_exposure"] = float(state.log_exposure)
    if transport is not None:
        trace.info["transport"] = {"recordings": refreshes, "seconds": round(transport.seconds, 3),
                                   "pixels": transport.pixels, "foreground": transport.foreground,
                                   "bytes": transport.nbytes}
    yield {"phase": "loop", "env": env}
    if run.sun:
        trace.info["sun"] = {**sun_summary(state.sun_uv.detach(), sun_irradiance, env),
                             "merged_spots": merged, "radius_deg": radius, "radius_losses": radius_losses}
    if transport is not None:
        pinned = seen_weight(transport_weights(transport), transport.height)
        env = keep_what_the_views_see(env, init.env, pinned)
        trace.info["pinned_by_views"] = round(float(pinned.mean()), 4)
    yield {"phase": "kept", "env": env}
    env, materials, refine_trace = refine(problem, env, state.materials, run.cfg.refine, run.cfg,
                                          seed + 1, polish_height(init), progress)
    trace.info["refine"] = refine_trace.summary()
    trace.nan_skips += refine_trace.nan_skips
    if store:
        store.remove()
    yield {"phase": "refined", "env": env,
           "result": DPSResult(Decomposition(env, materials, trace), strip_frames(state.snapshots, STRIP_FRAMES))}


def dps_sample(problem: InverseProblem, prior: Prior, init: Decomposition, cfg: DPSConfig, seed: int,
               progress: bool = True, checkpoint: Path | None = None, checkpoint_every: int = CHECKPOINT_EVERY,
               radiance_scale: float | None = None) -> DPSResult:
    """One posterior sample (dps_phases, run to its end)."""
    for phase in dps_phases(problem, prior, init, cfg, seed, progress, checkpoint, checkpoint_every, radiance_scale):
        pass
    return phase["result"]
