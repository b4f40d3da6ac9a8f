"""Small studies of the method's behaviour, shared by benchmarks and tests.

`roughness_point` reproduces the shape of the paper's Fig. 9: one object rendered with materials
from mirror-like to diffuse under the same natural light (a procedural outdoor map with buildings and
a sun, which no prior saw); `dps` samples of a mirror-like object agree on the
illumination (it is seen in reflections), while a diffuse object leaves it ambiguous, so the
env-map spread across samples (sigma2_sample) grows with roughness.
"""

from __future__ import annotations

from dataclasses import field, replace
from pathlib import Path

from dpi.capture import load_capture
from dpi.pipeline import resolve_config
from dpi.prior.sample import Prior
from dpi.render import RenderConfig
from dpi.settings import Count, settings
from dpi.solve.dps import DPSConfig, dps_sample
from dpi.solve.dps.refine import RefineConfig
from dpi.solve.init import InitConfig, path_traced_init
from dpi.solve.problem import InverseProblem, ProblemConfig
from dpi.spread import normalized_env, sample_variance
from dpi.synth.capture import SynthConfig, make_synthetic_capture


@settings
class SweepConfig:
    """Sizes of one roughness-sweep run: small views and map (32 rows), the workflow's render and init.

    The light is a natural map, not Mitsuba's sun-and-sky: a mirror of a featureless sky shows little
    more than a rough object does."""

    synth: SynthConfig = field(default_factory=lambda: SynthConfig(views=8, held_out_every=0, width=32, height=32,
                                                                   spp=64, environment="outdoor",
                                                                   environment_seed=31))
    problem: ProblemConfig = field(default_factory=lambda: ProblemConfig(texture_size=32))
    render: RenderConfig = field(default_factory=RenderConfig)
    init: InitConfig = field(default_factory=lambda: InitConfig.from_dict(resolve_config()["init"]))
    dps: DPSConfig = field(default_factory=lambda: DPSConfig(steps=50, refine=RefineConfig(iterations=20)))
    samples: Count = 6
    """dps samples per point: a variance from n samples has a relative variance of 2 / (n - 1), so too few let one
    repeat decide Fig. 9's ratio"""


def material_for(roughness: float) -> dict[str, float]:
    """Mirror-like objects are metallic; the others dielectric, as in the paper's sweep."""
    return {"roughness": roughness, "metallic": 1.0 if roughness <= 0.1 else 0.0, "roughness_variation": 0.0}


def roughness_point(roughness: float, repeat: int, prior: Prior, folder: str | Path, settings: SweepConfig,
                    threads: int | None = None) -> dict[str, float]:
    """env sigma2_sample of `samples` dps samples at one roughness; each repeat has its own capture noise,
    init seed and sample seed stream, so repeats are independent."""
    render = replace(settings.render, threads=threads)
    root = Path(folder) / f"rough_{roughness:.3f}_{repeat}"
    make_synthetic_capture(root, replace(settings.synth, **material_for(roughness), seed=settings.synth.seed + repeat),
                           threads=threads, progress=False, overwrite=True)
    problem = InverseProblem(load_capture(root), settings.problem, render)
    init = path_traced_init(problem, settings.init, seed=repeat, progress=False)
    envs = [dps_sample(problem, prior, init, settings.dps, seed=100 + 1000 * repeat + k, progress=False).decomposition.env
            for k in range(settings.samples)]
    return {"roughness": roughness, "metallic": material_for(roughness)["metallic"], "repeat": repeat,
            "samples": settings.samples,
            "env_sigma2_sample": sample_variance([normalized_env(e.numpy()) for e in envs])}
