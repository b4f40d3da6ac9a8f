"""The posterior methods: name -> settings dataclass, the function that draws one sample, and whether
it uses the diffusion prior. The one list the config check, the sample stage, the rules' wildcard
and the `dpi` command read.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator

import torch

from dpi.prior.sample import Prior, write_grid
from dpi.solve.adaptive import AdaptiveConfig, plan_steps
from dpi.solve.classic import ClassicConfig, classic_sample
from dpi.solve.decomposition import Decomposition
from dpi.solve.dip import DIPConfig, dip_sample
from dpi.solve.dps import DPSConfig, dps_phases
from dpi.solve.gan import GANConfig, gan_sample
from dpi.solve.priors import PRIOR_NAMES
from dpi.solve.reni import RENIConfig, reni_sample
from dpi.solve.problem import InverseProblem
from dpi.solve.sds import SDSConfig, sds_sample

X0_STRIP = "x0_strip.png"
"""dps: x0_hat during sampling, next to the sample's files"""


@dataclass
class SampleJob:
    """What drawing one posterior sample needs: the problem, the initialisation (both in normalised units),
    the method's settings, the seed, the prior (methods that use it), and where the sample goes."""

    problem: InverseProblem
    init: Decomposition
    settings: Any
    seed: int
    out_dir: Path
    resume: Path
    """the loop's resume state (methods that save one)"""
    prior: Prior | None = None
    radiance_scale: float | None = None
    """the problem's radiance per unit of the prior's (scene.yaml's, over the exposure; None: estimated)"""
    adaptive: AdaptiveConfig | None = None
    progress: bool = True


@dataclass(frozen=True)
class Method:
    """One posterior method."""

    settings: type
    """its settings dataclass: a `method_params` entry (less `samples`) is its `from_dict` input"""
    sample: Callable[[SampleJob], Decomposition]
    """draws one sample (its trace included) in the problem's normalised units"""
    needs_prior: bool = False
    """uses the diffusion prior (checkpoint of the scene's family)"""
    adaptive_steps: bool = False
    """runs fewer diffusion steps on a diffuse scene (adaptive.diffuse_*)"""


def classic(name: str) -> Callable[[SampleJob], Decomposition]:
    """The joint fit with the hand-crafted prior `name` (none, global_norm, smoothness, chromaticity)."""
    return lambda job: classic_sample(job.problem, name, job.init, job.settings, job.seed, job.progress, job.resume)


def dip(job: SampleJob) -> Decomposition:
    """Deep image prior: a seeded CNN generates the map."""
    return dip_sample(job.problem, job.init, job.settings, job.seed, job.progress, job.resume)


def gan(job: SampleJob) -> Decomposition:
    """The GAN baseline: a trained generator inverted by pivotal tuning."""
    return gan_sample(job.problem, job.init, job.settings, job.seed, job.progress, job.resume)


def reni(job: SampleJob) -> Decomposition:
    """RENI: a trained rotation-equivariant field of light, its latent fitted to the views."""
    return reni_sample(job.problem, job.init, job.settings, job.seed, job.progress, job.resume)


def sds(job: SampleJob) -> Decomposition:
    """Score distillation with the diffusion prior."""
    return sds_sample(job.problem, job.prior, job.init, job.settings, job.seed, job.progress, job.radiance_scale)


def dps_phases_of(job: SampleJob) -> Iterator[dict[str, Any]]:
    """The job's dps sample phase by phase (dpi.solve.dps.loop.dps_phases), fewer steps on a diffuse scene
    (dpi.solve.adaptive, recorded in the trace's info of the last phase's result)."""
    cfg = job.settings
    requested = cfg.steps
    cfg.steps, reason = plan_steps(job.init.materials, cfg.steps, job.adaptive or AdaptiveConfig())
    print(f"adaptive: {reason}", flush=True)
    for phase in dps_phases(job.problem, job.prior, job.init, cfg, job.seed, job.progress, job.resume,
                            radiance_scale=job.radiance_scale):
        if "result" in phase:
            phase["result"].decomposition.trace.info["adaptive"] = {"steps": cfg.steps, "requested_steps": requested,
                                                                   "reason": reason}
        yield phase


def dps(job: SampleJob) -> Decomposition:
    """The paper's diffusion posterior sampling (dps_phases_of, to its end) and the x0_hat strip next to the sample."""
    for phase in dps_phases_of(job):
        pass
    result = phase["result"]
    write_grid(job.out_dir / X0_STRIP, torch.stack(result.snapshots), columns=len(result.snapshots))
    return result.decomposition


REGISTRY: dict[str, Method] = {
    **{name: Method(ClassicConfig, classic(name)) for name in PRIOR_NAMES},
    "sds": Method(SDSConfig, sds, needs_prior=True),
    "dip": Method(DIPConfig, dip),
    "gan": Method(GANConfig, gan),
    "reni": Method(RENIConfig, reni),
    "dps": Method(DPSConfig, dps, needs_prior=True, adaptive_steps=True),
}
METHODS = tuple(REGISTRY)
"""the methods, in the order tables and figures list them (the paper's method last)"""
METHOD_CONFIGS: dict[str, type] = {name: method.settings for name, method in REGISTRY.items()}
"""method name -> settings dataclass; a `method_params` entry is that class's `from_dict` input"""
DIFFUSION_METHODS = tuple(name for name, method in REGISTRY.items() if method.needs_prior)
"""methods that use the diffusion prior"""


def method_config(method: str, values: dict[str, Any] | None) -> Any:
    """The settings of `method` from its `method_params` entry (without `samples`); errors name the bad key."""
    if method not in METHOD_CONFIGS:
        raise ValueError(f"unknown method {method!r}; available: {', '.join(METHODS)}")
    return METHOD_CONFIGS[method].from_dict(values or {})
