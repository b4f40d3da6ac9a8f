"""Where a `dps` sample starts: its materials, what a glossy init changes, and the transport it records.

Whether the init is glossy (dpi.solve.init.is_glossy) is read here once, by `glossy_start`, and decides the rest:
a glossy init's sample records a finer transport and draws the direct light only for the bright texels (its narrow
lobe sampled by the BSDF), skips the map's solve (a mirror's views pin the light where they reflect it), takes two
data updates a step, refines twice as long (the loop does not move the roughness a mirror's views hinge on), and
polishes its map per texel, freely where the map has the prior's rows (a rough init's polish lives on its transport's
grid). A rough init's sample runs its settings as they are, and gets a parametric sun where the sun's rule allows
(dpi.solve.dps.sun_choice).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import torch

from dpi.solve.decomposition import Decomposition
from dpi.solve.init import METAL_TEXEL, is_glossy, starting_materials
from dpi.solve.materials import MaterialTextures
from dpi.solve.problem import InverseProblem
from dpi.solve.transport import (MAX_TRANSPORT_HEIGHT, ROUGH_TRANSPORT_HEIGHT, LightTransport, TransportConfig,
                                 record_transport)

GLOSSY_INNER_STEPS = 2
"""a glossy init's data updates a step (it skips the map's solve)"""
GLOSSY_REFINE_FACTOR = 2
"""a glossy init's refinement runs this many times `refine.iterations`"""
GLOSSY_LR_TEXELS = 0.02
"""a glossy init's per-texel polish rate on a map with at least the prior's rows ..."""
GLOSSY_COARSE_LR_TEXELS = 0.005
"""... and on a coarser map: a light touch (fitting reflections finer than its texels only sharpens it away from the
light)"""


def glossy_start(init: Decomposition) -> bool:
    """Whether a sample from `init` starts as a glossy object's (module notes)."""
    return is_glossy(init.materials)


def sample_start_materials(init: Decomposition) -> MaterialTextures:
    """The materials a sample from `init` starts from, a copy: every posterior method's start (a grey albedo, the
    init's roughness, dpi.solve.init.starting_materials), but the texels the init reads as metal (metallic above
    METAL_TEXEL) keep its metallic: a metal part stays metal."""
    materials = starting_materials(init)
    with torch.no_grad():
        metal = init.materials.metallic > METAL_TEXEL
        materials.metallic[metal] = init.materials.metallic[metal]
    return materials


def settings_for_init(cfg: Any, init: Decomposition, prior_rows: int) -> Any:
    """The dps settings (dpi.solve.dps.config.DPSConfig) a sample from `init` runs with, under a prior of `prior_rows`
    rows (module notes): a rough init's are `cfg` itself."""
    if not glossy_start(init):
        return cfg
    proximal = replace(cfg.proximal, inner_steps=GLOSSY_INNER_STEPS, map_solve=0)
    lr_texels = GLOSSY_LR_TEXELS if init.env.shape[0] >= prior_rows else GLOSSY_COARSE_LR_TEXELS
    refine = replace(cfg.refine, iterations=cfg.refine.iterations * GLOSSY_REFINE_FACTOR, lr_texels=lr_texels)
    return replace(cfg, proximal=proximal, refine=refine)


def polish_height(init: Decomposition) -> int | None:
    """The rows of the refinement's polish (dpi.solve.dps.refine): a rough init's on its transport's grid, as finely
    as its views fix the light; a glossy init's per texel (None: a mirror's views resolve the map's texels)."""
    return None if glossy_start(init) else ROUGH_TRANSPORT_HEIGHT


def start_transport(problem: InverseProblem, init: Decomposition, start: MaterialTextures, settings: TransportConfig,
                    seed: int) -> LightTransport:
    """The transport a sample from `init` records under its starting materials `start`, with `seed` (module notes:
    a glossy init's the finer one with the bright texels' direct draws; a rough one's the low frequencies its views
    see, every texel drawn)."""
    glossy = glossy_start(init)
    return record_transport(problem, start, init.env, settings, seed,
                            MAX_TRANSPORT_HEIGHT if glossy else ROUGH_TRANSPORT_HEIGHT, not glossy)
