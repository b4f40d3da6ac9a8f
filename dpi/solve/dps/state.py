"""What one `dps` sample carries: the fixed run (problem, prior, schedule, settings) and the loop state.

A sampler's step function takes both, advances the state by one schedule step and returns the
step's record for the trace (`skipped` says why a step did not update; `nan_inner` counts skipped
inner updates; `seconds_*` time its parts).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import torch

from dpi.io.images import luminance
from dpi.light.sunlight import SUN_RADIUS_DEG as DISC_RADIUS_DEG
from dpi.light.sunlight import merge_spots_into_sun
from dpi.prior.diffusion import Diffusion, model_output_with_random_roll, model_timesteps, p_mean_variance
from dpi.prior.sample import Prior
from dpi.solve.decomposition import Decomposition
from dpi.solve.dps.sun_choice import SunConfig
from dpi.solve.materials import MaterialTextures
from dpi.solve.prior_space import resample_env
from dpi.solve.problem import InverseProblem
from dpi.solve.sun_model import sun_env


DARK_FLOOR = 1e-6
"""radiance floor (times the prior's median) before the logarithm (the paper's curve reaches 0)"""


def recentre_(log_map: torch.Tensor, median_target: float) -> float:
    """Shift the map's log radiance so its median luminance is the prior's (in place); returns the shift
    for the exposure to take over. Map level and exposure are one degree of freedom: without this the
    level drifts and the encoded map saturates."""
    with torch.no_grad():
        shift = float(torch.log(luminance(torch.exp(log_map[0]).permute(1, 2, 0)).median() / median_target))
        log_map -= shift
    return shift


@dataclass
class DPSRun:
    """What stays fixed during one posterior sample."""

    problem: InverseProblem
    prior: Prior
    sampler: Any
    """the sampler's own settings (dpi.solve.dps.config.SAMPLERS)"""
    cfg: Any
    """the sample's dps settings (dpi.solve.dps.config.DPSConfig, adapted to the init by
    dpi.solve.dps.start.settings_for_init)"""
    diffusion: Diffusion
    seed: int
    scale: float
    """scene radiance per unit of the prior's normalised radiance (times exp(log-exposure))"""
    data_norm: float
    """mean squared foreground radiance of the training views (makes the data term relative)"""
    first_index: int
    """schedule index of the first executed step (the last index, or lower when starting from the noised init)"""
    sun: SunConfig | None = None
    """the map's parametric sun next to the prior's sky (dpi.solve.sun_model), None without one"""
    init: Decomposition | None = None
    """the initialisation the sample starts from"""

    @property
    def num_steps(self) -> int:
        """Executed reverse steps."""
        return self.first_index + 1

    def index(self, n: int) -> int:
        """Schedule index of executed step n (the first executed step is the noisiest)."""
        return self.first_index - n

    def env(self, radiance: torch.Tensor, state: "DPSState", height: int | None = None) -> torch.Tensor:
        """Prior-resolution normalised radiance (1, 3, h, 2h) -> scene env map (H, 2H, 3) at `height` rows
        (default the problem's), times the state's exposure, plus its sun."""
        height = height or self.problem.settings.env_height
        env = self.sky(radiance, state, height)
        return env + sun_env(state.sun_uv, self.sun_irradiance(state), height) if self.sun else env

    def sky(self, radiance: torch.Tensor, state: "DPSState", height: int) -> torch.Tensor:
        """Prior-resolution normalised radiance (1, 3, h, 2h) -> the scene map without its sun (H, 2H, 3) at
        `height` rows, times the state's exposure."""
        return self.scale * torch.exp(state.log_exposure) * resample_env(radiance, height)

    def written_sky(self, radiance: torch.Tensor, state: "DPSState") -> tuple[torch.Tensor, torch.Tensor, int]:
        """The sample's map at the problem's height without its sun: with a sun, any bright spot the prior drew in the
        sky is moved into the fitted sun (dpi.light.sunlight.merge_spots_into_sun), so one sun remains; returns the
        sky, the sun's irradiance (zero without one) and the number of spots merged."""
        sky = self.sky(radiance, state, self.problem.settings.env_height)
        if not self.sun:
            return sky, torch.zeros(3), 0
        return merge_spots_into_sun(sky, self.sun_irradiance(state), radiance.shape[-2])

    def with_sun(self, sky: torch.Tensor, irradiance: torch.Tensor, state: "DPSState",
                 sun_radius_deg: float = DISC_RADIUS_DEG) -> torch.Tensor:
        """A written sky (`written_sky`) with the sample's sun of `irradiance` drawn as a disc of `sun_radius_deg`
        (the sky itself without a sun)."""
        return sky + sun_env(state.sun_uv, irradiance, sky.shape[0], sun_radius_deg) if self.sun else sky

    def written_env(self, radiance: torch.Tensor, state: "DPSState",
                    sun_radius_deg: float = DISC_RADIUS_DEG) -> tuple[torch.Tensor, torch.Tensor, int]:
        """The sample's map at the problem's height (`written_sky` with its sun drawn as a disc of `sun_radius_deg`),
        the sun's irradiance and the number of spots merged."""
        sky, irradiance, merged = self.written_sky(radiance, state)
        return self.with_sun(sky, irradiance, state, sun_radius_deg), irradiance, merged

    def sun_irradiance(self, state: "DPSState") -> torch.Tensor:
        """(3,) the state's sun in scene radiance units (its log irradiance is in the prior's, times the exposure)."""
        return self.scale * torch.exp(state.log_exposure + state.sun_log)

    def views(self, generator: torch.Generator) -> list[int]:
        """Training views of one rendered data term (the sampler's views_per_step)."""
        return self.problem.sample_views(self.sampler.views_per_step, generator)

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
    """global log-exposure of the map (scalar): absorbs the light/albedo scale ambiguity"""
    log_map: torch.Tensor
    """the map's normalised log radiance (1, 3, h, 2h) during a step's data updates (samplers that keep one)"""
    sun_uv: torch.Tensor
    """(2,) map coordinates of the sun (used when the run has one)"""
    sun_log: torch.Tensor
    """(3,) log irradiance of the sun per channel, in the prior's normalised units (times the exposure)"""
    optimizer: torch.optim.Adam
    generator: torch.Generator
    normal_albedo: torch.Tensor | None = None
    """the albedo the views' normal equations in use were formed under, and the step they were formed at
    (`normal_step`; -1: none yet): saved, so a resumed sample forms the same ones"""
    normal_step: torch.Tensor = field(default_factory=lambda: torch.tensor(-1))
    snapshots: list[torch.Tensor] = field(default_factory=list)
    """x0_hat at a few steps, for the progress strip"""
    extra: dict[str, Any] = field(default_factory=dict)
    """a sampler's caches (not saved in resume files: rebuilt from the tensors, e.g. the light transport)"""

    def __post_init__(self) -> None:
        if self.normal_albedo is None:
            self.normal_albedo = self.materials.albedo.detach().clone()

    def tensors(self) -> dict[str, torch.Tensor]:
        """The loop's variables by name (for resume files)."""
        return {"x": self.x, **dict(self.materials.items()), "log_exposure": self.log_exposure,
                "log_map": self.log_map, "sun_uv": self.sun_uv, "sun_log": self.sun_log,
                "normal_albedo": self.normal_albedo, "normal_step": self.normal_step}


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


def log_radiance(run: DPSRun, x0: torch.Tensor) -> torch.Tensor:
    """A prior-space map's normalised log radiance, dark texels floored at DARK_FLOOR x the prior's median."""
    return torch.log(run.prior.encoding.to_radiance(x0).clamp_min(DARK_FLOOR * run.prior.median_target))


def network_step(run: DPSRun, x: torch.Tensor, i: int, generator: torch.Generator) -> dict[str, torch.Tensor]:
    """p_mean_variance of the randomly rolled network output at schedule index i (x0 clamped to [-1, 1])."""
    t = torch.full((1,), i, dtype=torch.long)
    output = model_output_with_random_roll(run.prior.model, x, model_timesteps(run.diffusion, t), generator)
    return p_mean_variance(run.diffusion, output, x, t)


def predicted_step(run: DPSRun, state: DPSState, n: int, laps: Laps) -> tuple[dict[str, Any], torch.Tensor | None]:
    """Step n's network prediction without a graph (the samplers that need no backward through it): the step's
    record and x0_hat, kept in the snapshots; or, for a non-finite output, the record saying the step was
    skipped and None (x_t is kept)."""
    i = run.index(n)
    with torch.no_grad():
        p = network_step(run, state.x, i, state.generator)
    laps.lap("network")
    record: dict[str, Any] = {"step": n, "t": int(run.diffusion.timestep_map[i])}
    if not finite(p["x0"]):
        return {**record, "skipped": "non-finite network output", **laps.record()}, None
    state.snapshots.append(p["x0"][0])
    return record, p["x0"]


def finite(*tensors: torch.Tensor) -> bool:
    """True when every tensor is free of NaN/Inf."""
    return all(bool(torch.isfinite(t).all()) for t in tensors)
