"""Path-traced initialisation (DESIGN step 1): a free env map and materials fitted jointly.

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
    """Where every posterior method starts: a grey albedo with, on a rough object, the init's median
    roughness and median metallic everywhere, and on a glossy one (`is_glossy`) the init's textures.
    A rough object's views see its light blurred, and the init's textures fitted under it carry its
    errors (on the sun study's blob, roughness 0.55 against the truth's 0.30, metal up to 0.5 where the
    sun's highlights fall): with the true light fixed, the fit from them gave held-out views 1.4-2.5 dB
    worse than from the medians. A mirror's views resolve its materials, and there the textures are
    the better start (posterior study, glossy scene: 1.5-2.7 dB of views for every method)."""
    materials = init.materials.detached()
    with torch.no_grad():
        materials.albedo.fill_(START_ALBEDO)
        if not is_glossy(materials):
            materials.roughness.fill_(float(materials.roughness.median()))
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
