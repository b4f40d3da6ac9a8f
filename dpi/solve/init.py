"""Path-traced initialisation, the first step of every method: a free env map and materials fitted jointly.

Its roughness and metallic seed every posterior method; its albedo is reset by the methods.
The starting map is uniform, at the level that makes a grey (albedo 0.5) diffuse object match
the mean observed foreground radiance.
"""

from __future__ import annotations

import math
from pathlib import Path

import torch

from dpi.materials import MaterialTextures
from dpi.solve.decomposition import Decomposition
from dpi.solve.optimize import OptimizeConfig, fit
from dpi.solve.problem import InverseProblem
from dpi.solve.trace import Trace

START_ALBEDO, START_ROUGHNESS, START_METALLIC = 0.5, 0.5, 0.0


def starting_log_env(problem: InverseProblem) -> torch.Tensor:
    """Uniform log-radiance explaining the mean foreground radiance with a grey diffuse object."""
    values = [img[mask].mean() for i in problem.train_ids
              for img, mask in [(problem.images[i], problem.masks[i])]]
    level = max(float(torch.stack(values).mean()) / START_ALBEDO, 1e-4)
    h = problem.settings.env_height
    return torch.full((h, 2 * h, 3), math.log(level))


GLOSSY_ROUGHNESS = 0.3
"""an init whose roughness 25th percentile is below this is glossy (untouched texels keep the start's
0.5, so the median misses a shiny object)"""


def is_glossy(materials: MaterialTextures, threshold: float = GLOSSY_ROUGHNESS) -> bool:
    """True when the roughness 25th percentile is below `threshold`: a shiny object, at least in part."""
    return float(torch.quantile(materials.roughness.detach().flatten(), 0.25)) < threshold


def starting_materials(init: Decomposition) -> MaterialTextures:
    """Where every posterior method starts: a grey albedo, the init's roughness, and on a rough object
    the init's median metallic everywhere (on a glossy one, `is_glossy`, its metallic texture).

    The init fits a rough object's materials under a blurred light and explains the highlights it
    cannot place with metal: on the sun study's blob its metallic reaches 0.5 where the sun's
    highlights fall (truth 0). Starting from the median metallic, `dps`'s held-out views gain
    0.4-0.6 dB on the sun study, 0.2 on the demo and 0.07 on the posterior study's ambiguous scenes
    (docs/studies.md, "the material start"). A mirror's views resolve its materials: there the texture starts."""
    materials = init.materials.detached()
    with torch.no_grad():
        materials.albedo.fill_(START_ALBEDO)
        if not is_glossy(materials):
            materials.metallic.fill_(float(materials.metallic.median()))
    return materials


def path_traced_init(problem: InverseProblem, cfg: OptimizeConfig, seed: int, progress: bool = True,
                     checkpoint: Path | None = None) -> Decomposition:
    """Fit env map + materials from constant starting values; returns them with the trace (`checkpoint`:
    the fit's resume file)."""
    trace = Trace(info={"stage": "init", "config": vars(cfg).copy(), "seed": seed})
    materials = MaterialTextures.constant(problem.settings.texture_size, START_ALBEDO, START_ROUGHNESS,
                                          START_METALLIC)
    log_env, materials = fit(problem, starting_log_env(problem), materials, cfg, seed, trace, progress=progress,
                             checkpoint=checkpoint)
    return Decomposition(log_env.exp(), materials, trace)
