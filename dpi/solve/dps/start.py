"""Where a `dps` sample starts: its materials, recorded into its light transport."""

from __future__ import annotations

import torch

from dpi.solve.decomposition import Decomposition
from dpi.solve.init import METAL_TEXEL, starting_materials
from dpi.solve.materials import MaterialTextures


def sample_start_materials(init: Decomposition) -> MaterialTextures:
    """The materials a sample from `init` starts from, a copy: every posterior method's start (a grey albedo, the
    init's roughness, dpi.solve.init.starting_materials), but the texels the init reads as metal (metallic above
    METAL_TEXEL) keep its metallic: a metal part stays metal."""
    materials = starting_materials(init)
    with torch.no_grad():
        metal = init.materials.metallic > METAL_TEXEL
        materials.metallic[metal] = init.materials.metallic[metal]
    return materials
