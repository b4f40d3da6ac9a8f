"""Diffusion posterior sampling with an optimisable measurement operator (the paper's method, `dps`).

Reverse diffusion over the prior's image space x (encoded env maps in [-1, 1]), guided by the
renderer, with the materials optimised jointly; after the last step the materials are refined under
the clean map, which keeps its detail and gets a smooth gain and a light per-texel polish
(`refine_env`). How one reverse step uses the data is the `sampler` setting (dpi.solve.samplers: the
paper's gradient guidance, or a proximal x0-space step).

`posterior_steps` is the loop: a generator that runs one sampler step per schedule step and yields
its record, like guided-diffusion's `p_sample_loop_progressive`; `dps_sample` consumes it for the
trace, the progress bar and the resume file, and benchmarks/dps_step.py for its timings. A step
with a non-finite network output, loss or gradient does not update (it is counted in the trace).
Given a `checkpoint` file the loop saves its state there every `checkpoint_every` steps and a
rerun continues from it (see dpi.solve.checkpoint); the refinement, short, is simply run again.
The file is deleted when the sample is done.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import torch
from tqdm import tqdm

from dpi.materials import MaterialTextures
from dpi.prior.data import radiance_scale
from dpi.prior.diffusion import q_sample
from dpi.prior.sample import Prior
from dpi.settings import settings_from_dict
from dpi.solve.checkpoint import LoopState, checkpoint_for, problem_identity
from dpi.solve.decomposition import Decomposition
from dpi.solve.init import GLOSSY_ROUGHNESS, is_glossy, starting_materials
from dpi.solve.optimize import EnvModel, FreeEnvMap, OptimizeConfig, fit_env_model
from dpi.solve.problem import InverseProblem
from dpi.solve.samplers import SAMPLERS, DPSRun, DPSState, resample_env, rho_schedule
from dpi.solve.smooth_gain import MAX_ORDER, SmoothGain
from dpi.solve.sun import extract_sun, sun_summary
from dpi.solve.trace import Trace

RHO_SCHEDULES = ("linear", "step", "constant")
MAP_UPDATES = ("adam", "normalized")
REFINE_ENV = ("fixed", "gain", "polish", "texels")
SUN_MODES = ("auto", "on", "off")
SUN_FAMILIES = ("outdoor",)
"""prior families whose maps get a parametric sun under sun: auto"""
CHECKPOINT_EVERY = 10
"""reverse steps between two saves of the resume state (a save costs far less than one step)"""


SAMPLER_DEFAULTS: dict[str, dict[str, Any]] = {"proximal": {"start_noise": 0.4, "views_per_step": 4, "sun": "auto"},
                                               "paper": {"start_noise": 1.0, "views_per_step": 1, "sun": "off"}}
"""Settings a sampler brings where the config leaves them unset: proximal's won the posterior study
(benchmarks/posterior_study.py); the paper's loop starts from pure noise with one view per step, as in
the reference"""


@dataclass
class DPSConfig:
    """Settings of the `dps` method (defaults: the CPU preset)."""

    sampler: str = next(iter(SAMPLERS))
    """how a reverse step uses the data: proximal (x0-space data steps, no network backward) or paper"""
    steps: int = 100
    """reverse-diffusion steps (respaced from the prior's 1000; the paper uses 1000)"""
    views_per_step: int | None = None
    """training views rendered per data term (None: the sampler's, SAMPLER_DEFAULTS)"""
    spp: int | None = None
    """proximal: samples per pixel of the data term's renders (None: the renderer's)"""
    guidance_bound: float = 0.1
    """paper: max-abs of the rendering-loss gradient after rescaling"""
    rho_start: float = 0.1
    """paper: guidance weight during the first part of the steps"""
    rho_end: float = 1.0
    """paper: guidance weight at the last step"""
    rho_schedule: str = "linear"
    """paper: linear: rho_start, then linear to rho_end (outdoor); step: jump to rho_end (indoor); constant"""
    rho_switch: float = 0.5
    """paper: fraction of steps run at rho_start"""
    inner_steps: int = 2
    """proximal: joint data updates of map, materials and exposure per reverse step"""
    lr_map: float = 0.05
    """proximal: step of the map's log radiance per data update (Adam's rate, or the RMS of a normalized step)"""
    map_update: str = "adam"
    """proximal: adam (per-texel Adam) or normalized (gradient scaled to RMS lr_map over the map)"""
    warm_start: bool = True
    """proximal: start each step's data updates from the previous step's map instead of from x0_hat"""
    start_noise: float | None = None
    """noise level the reverse diffusion starts from, as a fraction of the schedule: 1 starts from pure
    noise; less starts from the init map noised to that level (SDEdit) and runs that fraction of the steps
    (None: the sampler's, SAMPLER_DEFAULTS)"""
    prox_weight: float = 0.5
    """proximal: weight of ||z - x0_hat||^2 per unit abar_t / (1 - abar_t)"""
    noise_mix: float = 0.5
    """proximal: share zeta of fresh noise in the re-noising (0: deterministic DDIM, 1: all fresh)"""
    material_start: float = 0.3
    """proximal: fraction of the steps before the materials start to move"""
    lr_albedo: float = 2e-2
    lr_roughness: float = 1.5e-2
    lr_metallic: float = 1e-2
    refine_iterations: int = 200
    """Adam iterations of the refinement: the materials under the final map (and its gain, `refine_env`)"""
    refine_views_per_step: int = 2
    refine_env: str = "polish"
    """what the refinement may change of the sampled map: fixed; gain, a smooth log gain (spherical harmonics
    up to refine_gain_order: the light's broad balance, which the views determine, dpi.solve.smooth_gain);
    polish, the gain and every texel (at refine_lr_texels, so they stay near the sample); texels, every texel"""
    refine_gain_order: int = 1
    """gain: highest spherical-harmonic band of the log gain (0-2; 1: a level and a tilt per channel, e.g. the
    ground against the sky; 2 fits the views better but bends the map away from the truth)"""
    refine_lr_gain: float = 0.03
    """Adam rate of the gain's coefficients during the refinement"""
    refine_lr_texels: float = 0.005
    """Adam rate of the texels' log radiance during the refinement (polish, texels): at most 1 over 200 steps"""
    sun: str | None = None
    """a parametric sun next to the prior's sky (dpi.solve.sun): on, off, or auto (on with the outdoor
    prior for objects that are not glossy); it starts from the init's brightest region (None: the
    sampler's, SAMPLER_DEFAULTS)"""
    sun_radius_deg: float = 25.0
    """radius around the init's brightest texel whose excess energy becomes the sun"""
    sun_min_roughness: float = GLOSSY_ROUGHNESS
    """sun: auto leaves it off for an init that `is_glossy` at this threshold: a glossy object mirrors the
    light, the views resolve its sun, and the sun's share prior only costs accuracy there"""
    sun_min_share: float = 0.05
    """the sun is kept only when that excess carries at least this share of the init map's energy"""
    sun_share: float = 0.55
    """the share of the map's energy the sun's prior expects: the median over the outdoor generator's
    clear skies with the sun above 10 deg (0.5-0.6 per elevation band; lower under clouds)"""
    sun_prior_weight: float = 0.01
    """weight of (logit share - logit sun_share)^2 next to the relative data term (0: the data alone)"""
    lr_sun: float = 0.05
    """Adam rate of the sun's log irradiance"""
    lr_sun_uv: float = 0.003
    """Adam rate of the sun's map coordinates (u spans 360 deg, v 180 deg)"""
    radiance_scale: float | None = None
    """scene radiance per unit of the prior's normalised radiance (None: estimated from init)"""
    strip_frames: int = 8
    """x0_hat snapshots kept for the progress strip"""

    def __post_init__(self) -> None:
        for key, value in SAMPLER_DEFAULTS.get(self.sampler, {}).items():
            if getattr(self, key) is None:
                setattr(self, key, value)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> "DPSConfig":
        """Config from a `method_params.dps` entry. YAML reads a bare `sun: on` / `sun: off` as a
        boolean; it means the mode of that name."""
        if isinstance(values.get("sun"), bool):
            values = {**values, "sun": "on" if values["sun"] else "off"}
        cfg = settings_from_dict(cls, values)
        if cfg.sampler not in SAMPLERS:
            raise ValueError(f"sampler must be one of {tuple(SAMPLERS)}, got {cfg.sampler!r}")
        if cfg.rho_schedule not in RHO_SCHEDULES:
            raise ValueError(f"rho_schedule must be one of {RHO_SCHEDULES}, got {cfg.rho_schedule!r}")
        if cfg.inner_steps < 1:
            raise ValueError(f"inner_steps must be >= 1, got {cfg.inner_steps}")
        if cfg.map_update not in MAP_UPDATES:
            raise ValueError(f"map_update must be one of {MAP_UPDATES}, got {cfg.map_update!r}")
        if cfg.refine_env not in REFINE_ENV:
            raise ValueError(f"refine_env must be one of {REFINE_ENV}, got {cfg.refine_env!r}")
        if not 0 <= cfg.refine_gain_order <= MAX_ORDER:
            raise ValueError(f"refine_gain_order must be 0..{MAX_ORDER}, got {cfg.refine_gain_order}")
        if cfg.sun not in SUN_MODES:
            raise ValueError(f"sun must be one of {SUN_MODES}, got {cfg.sun!r}")
        if not 0 < cfg.start_noise <= 1:
            raise ValueError(f"start_noise must be in (0, 1], got {cfg.start_noise}")
        return cfg


@dataclass
class DPSResult:
    """A dps decomposition and the x0_hat snapshots (prior space, (3, H, W) each) for the strip."""

    decomposition: Decomposition
    snapshots: list[torch.Tensor] = field(default_factory=list)


ADAM_BETAS = (0.9, 0.99)
"""the data loss falls by orders of magnitude during a sample: a short second-moment memory keeps
Adam's steps from stalling on the large gradients of the first steps"""


def material_optimizer(materials: MaterialTextures, cfg: DPSConfig, log_map: torch.Tensor, sun_uv: torch.Tensor,
                       sun_log: torch.Tensor) -> torch.optim.Adam:
    """Adam on albedo / roughness / metallic, the map's log radiance and the sun, each at its own rate
    (a sampler's step updates those whose gradient it computed)."""
    return torch.optim.Adam([{"params": [materials.albedo], "lr": cfg.lr_albedo},
                             {"params": [materials.roughness], "lr": cfg.lr_roughness},
                             {"params": [materials.metallic], "lr": cfg.lr_metallic},
                             {"params": [log_map], "lr": cfg.lr_map},
                             {"params": [sun_uv], "lr": cfg.lr_sun_uv},
                             {"params": [sun_log], "lr": cfg.lr_sun}], betas=ADAM_BETAS)


def estimate_radiance_scale(init_env: torch.Tensor, prior: Prior) -> float:
    """Scene radiance per unit of the prior's normalised radiance: the init map's median luminance
    over the median the prior was trained with (the same normalisation as its training maps)."""
    return radiance_scale(init_env.permute(2, 0, 1), prior.median_target)


def prior_to_env(x0: torch.Tensor, prior: Prior, scale: float, height: int) -> torch.Tensor:
    """Prior image (1, 3, h, w) -> scene env map (H, 2H, 3) in radiance, resampled to `height`."""
    return resample_env(scale * prior.encoding.to_radiance(x0), height)


def env_to_prior(env: torch.Tensor, prior: Prior, scale: float) -> torch.Tensor:
    """Scene env map (H, 2H, 3) -> prior image (1, 3, h, 2h): area-resampled, divided by `scale`, encoded."""
    radiance = torch.nn.functional.interpolate(env.permute(2, 0, 1)[None], size=(prior.height, 2 * prior.height),
                                               mode="area")
    return prior.encoding.with_scale(scale).to_prior(radiance)


def data_norm(problem: InverseProblem) -> float:
    """Mean squared foreground radiance over the training views (the relative data term's unit)."""
    values = [problem.images[i][problem.masks[i]].square().mean() for i in problem.train_ids]
    return max(float(torch.stack(values).mean()), 1e-30)


def start_run(problem: InverseProblem, prior: Prior, init: Decomposition, cfg: DPSConfig,
              seed: int) -> tuple[DPSRun, DPSState]:
    """The fixed part of one sample and its loop state at x_T ~ N(0, I) (the init's materials, grey albedo)."""
    generator = torch.Generator().manual_seed(seed)
    diffusion = prior.schedule(cfg.steps)
    scale = cfg.radiance_scale or estimate_radiance_scale(init.env, prior)
    first = int(round(cfg.start_noise * (diffusion.num_timesteps - 1)))
    sun = extract_sun(init.env, cfg.sun_radius_deg)
    glossy = is_glossy(init.materials, cfg.sun_min_roughness)
    has_sun = cfg.sun == "on" or (cfg.sun == "auto" and prior.family in SUN_FAMILIES and not glossy
                                  and sun.share >= cfg.sun_min_share)
    run = DPSRun(problem, prior, cfg, diffusion, seed, scale, rho_schedule(cfg, first + 1), data_norm(problem), first,
                 has_sun)
    materials = starting_materials(init)
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
    state = DPSState(x, materials, torch.zeros(()), log_map, sun_uv, sun_log,
                     material_optimizer(materials, cfg, log_map, sun_uv, sun_log), generator)
    return run, state


def posterior_steps(run: DPSRun, state: DPSState, start: int = 0) -> Iterator[dict[str, Any]]:
    """Run the sampler's reverse steps start .. end on `state`, yielding each step's record."""
    step = SAMPLERS[run.cfg.sampler]
    for n in range(start, run.num_steps):
        yield step(run, state, n)


def strip_frames(snapshots: list[torch.Tensor], count: int) -> list[torch.Tensor]:
    """`count` evenly spaced snapshots (all when fewer)."""
    if len(snapshots) <= count:
        return snapshots
    keep = np.linspace(0, len(snapshots) - 1, count).round().astype(int)
    return [snapshots[k] for k in keep]


def refine(problem: InverseProblem, env: torch.Tensor, materials: MaterialTextures, cfg: DPSConfig, seed: int,
           progress: bool = True) -> tuple[torch.Tensor, MaterialTextures, Trace]:
    """The last stage of a sample: Adam on the materials under the map (fixed, with a smooth gain, the
    gain and a polish, or every texel: refine_env); returns the map, the materials and the refinement's trace."""
    settings = OptimizeConfig(iterations=cfg.refine_iterations, views_per_step=cfg.refine_views_per_step,
                              optimize_env=cfg.refine_env != "fixed",
                              lr_env=cfg.refine_lr_texels if cfg.refine_env == "texels" else cfg.refine_lr_gain,
                              lr_albedo=cfg.lr_albedo, lr_roughness=cfg.lr_roughness, lr_metallic=cfg.lr_metallic)
    trace = Trace()
    log_env = env.clamp_min(1e-8).log()
    if cfg.refine_env == "texels":
        model: EnvModel = FreeEnvMap(log_env)
    else:
        polish = cfg.refine_lr_texels / cfg.refine_lr_gain if cfg.refine_env == "polish" else 0.0
        model = SmoothGain(log_env, cfg.refine_gain_order, polish)
    log_env, materials = fit_env_model(problem, model, materials.detached(), settings, seed, trace, progress=progress)
    return log_env.exp(), materials, trace


def dps_sample(problem: InverseProblem, prior: Prior, init: Decomposition, cfg: DPSConfig, seed: int,
               progress: bool = True, checkpoint: Path | None = None,
               checkpoint_every: int = CHECKPOINT_EVERY) -> DPSResult:
    """One posterior sample: reverse diffusion guided by the renderer, joint material steps, refinement.
    With a `checkpoint` file the sample continues from the state a killed run of it left there."""
    run, state = start_run(problem, prior, init, cfg, seed)
    trace = Trace(info={"method": "dps", "sampler": cfg.sampler, "seed": seed, "radiance_scale": run.scale,
                        "family": prior.family, "config": vars(cfg).copy()})
    store = checkpoint_for(checkpoint, checkpoint_every, "dps", vars(cfg), seed, run.scale, problem_identity(problem),
                           init.env, dict(init.materials.items()), prior.family, prior.model.state_dict())
    saved = store.resume(state.tensors(), state.optimizer, state.generator, trace) if store else None
    start = saved.step if saved else 0
    if saved:
        state.snapshots = list(saved.snapshots)
    bar = tqdm(total=run.num_steps, initial=start, desc=f"dps {cfg.sampler}", disable=not progress,
               mininterval=2.0)
    for record in posterior_steps(run, state, start):
        trace.nan_skips += int("skipped" in record) + record.pop("nan_inner", 0)
        trace.record(**record)
        bar.update(1)
        n = record["step"] + 1
        if store and n < run.num_steps and store.due(n, start):
            store.save(LoopState.capture(n, state.tensors(), state.optimizer, state.generator, trace,
                                         state.snapshots))
    bar.close()
    with torch.no_grad():
        env = run.env(prior.encoding.to_radiance(state.x.clamp(-1, 1)), state)
    trace.info["log_exposure"] = float(state.log_exposure)
    if run.sun:
        trace.info["sun"] = sun_summary(state.sun_uv.detach(), run.sun_irradiance(state).detach(), env)
    env, materials, refine_trace = refine(problem, env, state.materials, cfg, seed + 1, progress)
    trace.info["refine"] = refine_trace.summary()
    trace.nan_skips += refine_trace.nan_skips
    if store:
        store.remove()
    return DPSResult(Decomposition(env, materials, trace), strip_frames(state.snapshots, cfg.strip_frames))
