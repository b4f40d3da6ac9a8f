"""Path-traced initialisation, the first step of every method: a free env map and materials fitted jointly.

Its roughness and metallic seed every posterior method; its albedo is reset by the methods.
The starting map is uniform, at the level that makes a grey (albedo 0.5) diffuse object match
the mean observed foreground radiance; the textures start constant, as a rough dielectric. Under
that uniform map roughness changes nothing, so a mirror's roughness gets little gradient and stops
half-way, with its reflections smeared into the map. When the fit's roughness ends that way (its
25th percentile below `retry_below`), the init is fitted again from a glossy metal and keeps that
fit when it explains the views clearly better (docs/studies.md, "The init's start").
"""

from __future__ import annotations

import math
from pathlib import Path

import torch

from dpi.materials import MaterialTextures
from dpi.settings import Fraction, Steps, settings
from dpi.solve.decomposition import Decomposition
from dpi.solve.optimize import CHECKPOINT_EVERY, AdamFit, FreeEnvMap, OptimizeConfig
from dpi.solve.problem import InverseProblem
from dpi.solve.trace import Trace

START_ALBEDO = 0.5
ROUGH_START = (0.5, 0.0)
"""constant (roughness, metallic) the textures start from: a rough dielectric"""
GLOSSY_START = (0.1, 1.0)
"""the retry's (roughness, metallic): a glossy metal"""
RETRY_GAIN = 0.6
"""the retry is kept when its closing data loss is below this fraction of the first fit's: a metal under a free
map explains a rough object's views a little better too, a mirror's far better"""
CLOSING_STEPS = 20
"""steps at the end of a fit whose mean data loss compares two fits (the same seed: the same views and noise)"""


@settings
class InitConfig(OptimizeConfig):
    """The init's fit (config section `init`): Adam settings and the glossy retry."""

    iterations: Steps = 200
    """Adam steps of each fit (the rough one, and the glossy retry when it runs)"""
    retry_below: Fraction = 0.4
    """the fit is retried from GLOSSY_START when its roughness 25th percentile ends below this (0: never): a rough
    start stops half-way on a mirror (docs/studies.md, "The init's start")"""


def starting_log_env(problem: InverseProblem) -> torch.Tensor:
    """Uniform log-radiance explaining the mean foreground radiance with a grey diffuse object."""
    values = [img[mask].mean() for i in problem.train_ids
              for img, mask in [(problem.images[i], problem.masks[i])]]
    level = max(float(torch.stack(values).mean()) / START_ALBEDO, 1e-4)
    h = problem.settings.env_height
    return torch.full((h, 2 * h, 3), math.log(level))


GLOSSY_ROUGHNESS = 0.3
"""an init whose roughness 25th percentile is below this is glossy"""


def roughness_p25(materials: MaterialTextures) -> float:
    """The roughness texture's 25th percentile (untouched texels keep the start's, so the median misses a shiny
    object)."""
    return float(torch.quantile(materials.roughness.detach().flatten(), 0.25))


def is_glossy(materials: MaterialTextures, threshold: float = GLOSSY_ROUGHNESS) -> bool:
    """True when the roughness 25th percentile is below `threshold`: a shiny object, at least in part."""
    return roughness_p25(materials) < threshold


def starting_materials(init: Decomposition) -> MaterialTextures:
    """Where every posterior method starts: a grey albedo, the init's roughness, and on a rough object
    the init's median metallic everywhere (on a glossy one, `is_glossy`, its metallic texture).

    The init fits a rough object's materials under a blurred light and explains the highlights it cannot place
    with metal, so its metallic texture is a poor start there (docs/studies_log.md, "the material start"). A mirror's
    views resolve its materials: there the texture starts."""
    materials = init.materials.detached()
    with torch.no_grad():
        materials.albedo.fill_(START_ALBEDO)
        if not is_glossy(materials):
            materials.metallic.fill_(float(materials.metallic.median()))
    return materials


def closing_loss(trace: Trace) -> float:
    """Mean data loss over a fit's last CLOSING_STEPS steps."""
    losses = [step["data"] for step in trace.steps if step.get("data") is not None][-CLOSING_STEPS:]
    return sum(losses) / len(losses) if losses else math.inf


def retried(cfg: InitConfig, first_roughness_p25: float) -> bool:
    """Whether the first fit's roughness (its 25th percentile) fell far enough to retry from GLOSSY_START."""
    return first_roughness_p25 < cfg.retry_below


def retry_kept(first_loss: float, retry_loss: float) -> bool:
    """Whether the retry explains the views clearly better than the first fit (closing losses)."""
    return retry_loss < RETRY_GAIN * first_loss


def start_fit(problem: InverseProblem, cfg: InitConfig, start: tuple[float, float], seed: int) -> AdamFit:
    """The init's fit from the uniform starting map and constant (roughness, metallic) textures."""
    materials = MaterialTextures.constant(problem.settings.texture_size, START_ALBEDO, *start)
    return AdamFit(problem, FreeEnvMap(starting_log_env(problem)), materials, cfg, seed,
                   Trace(info={"stage": "init", "config": vars(cfg).copy(), "seed": seed, "start": list(start)}))


def path_traced_init(problem: InverseProblem, cfg: InitConfig, seed: int, progress: bool = True,
                     checkpoint: Path | None = None, checkpoint_every: int = CHECKPOINT_EVERY) -> Decomposition:
    """Fit env map + materials from ROUGH_START, retried from GLOSSY_START when the fit's roughness asks for it;
    returns the kept fit with its trace (`checkpoint`: the resume file; the retry's is its sibling)."""
    first = start_fit(problem, cfg, ROUGH_START, seed)
    first.resume(checkpoint, checkpoint_every)
    first.run(cfg.iterations, progress)
    fits = [first]
    if retried(cfg, roughness_p25(first.materials)):
        first.save()  # a kill during the retry does not redo the first fit
        retry = start_fit(problem, cfg, GLOSSY_START, seed)
        retry.trace.started = first.trace.started
        retry.resume(checkpoint and checkpoint.with_name(f"{checkpoint.stem}.glossy{checkpoint.suffix}"),
                     checkpoint_every)
        retry.run(cfg.iterations, progress)
        losses = closing_loss(first.trace), closing_loss(retry.trace)
        keep = retry_kept(*losses)
        fits = [retry, first] if keep else [first, retry]
        fits[0].trace.info["retry"] = {"first_roughness_p25": roughness_p25(first.materials),
                                       "first_closing_loss": losses[0], "glossy_closing_loss": losses[1],
                                       "kept": "glossy" if keep else "first"}
    log_env, materials = [fit.finish() for fit in fits][0]
    return Decomposition(log_env.exp(), materials, fits[0].trace)
