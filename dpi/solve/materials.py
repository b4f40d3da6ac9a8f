"""Material textures as torch tensors: albedo (R, R, 3), roughness and metallic (R, R, 1).

One container for what the optimisers update and what stages read and write as EXR files.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from dpi.io.exr import read_exr, write_exr
from dpi.io.images import resize
from dpi.io.layout import TEXTURE_NAMES, texture_file
from dpi.io.settings import Rate, settings

CHANNELS = dict(zip(TEXTURE_NAMES, (3, 1, 1)))
RANGES = {"albedo": (0.0, 1.0), "roughness": (0.02, 1.0), "metallic": (0.0, 1.0)}


FIXED_RATES = {"roughness": 1.5e-2, "metallic": 1e-2}
"""Adam learning rates of the roughness and metallic textures, the same in every fit"""


@settings
class MaterialRates:
    """The albedo's Adam learning rate, which the init, the optimisation-based methods, sds and dps inherit (dps
    sets its own, DPSConfig.lr_albedo); the other textures' rates are FIXED_RATES."""

    lr_albedo: Rate = 2e-2

    def rate(self, name: str) -> float:
        """The rate of texture `name` (albedo, roughness, metallic)."""
        return self.lr_albedo if name == "albedo" else FIXED_RATES[name]


@dataclass
class MaterialTextures:
    """Principled-BSDF textures in UV space (row 0 at v = 1, as Mitsuba's bitmaps)."""

    albedo: torch.Tensor
    roughness: torch.Tensor
    metallic: torch.Tensor

    @classmethod
    def constant(cls, size: int, albedo: float = 0.5, roughness: float = 0.5, metallic: float = 0.0) -> "MaterialTextures":
        """Uniform textures of size x size texels."""
        return cls(torch.full((size, size, 3), albedo), torch.full((size, size, 1), roughness),
                   torch.full((size, size, 1), metallic))

    def items(self) -> list[tuple[str, torch.Tensor]]:
        """(name, tensor) pairs in a fixed order."""
        return [(name, getattr(self, name)) for name in CHANNELS]

    def detached(self) -> "MaterialTextures":
        """Copies without autograd history."""
        return MaterialTextures(*(t.detach().clone() for _, t in self.items()))

    @torch.no_grad()
    def clamp_(self) -> "MaterialTextures":
        """Clamp every texture to its valid range in place."""
        for name, t in self.items():
            t.clamp_(*RANGES[name])
        return self

    def save(self, folder: str | Path) -> None:
        """Write albedo.exr, roughness.exr and metallic.exr into `folder`; a texture with a NaN or infinite texel is
        refused, naming it, before anything is written."""
        for name, t in self.items():
            if not torch.isfinite(t).all():
                raise ValueError(f"{folder}: refusing to save a non-finite {name} texture")
        for name, t in self.items():
            write_exr(Path(folder) / texture_file(name), t.detach().cpu().numpy())

    @classmethod
    def load(cls, folder: str | Path, size: int | None = None) -> "MaterialTextures":
        """Read the three EXRs of `folder`, optionally resampled to size x size."""
        tensors = []
        for name, ch in CHANNELS.items():
            data = read_exr(Path(folder) / texture_file(name))[..., :ch]
            tensors.append(resize_texture(torch.from_numpy(np.ascontiguousarray(data)), size))
        return cls(*tensors)


def resize_texture(t: torch.Tensor, size: int | None) -> torch.Tensor:
    """Area/bilinear resample of an (R, R, C) texture to size x size (no-op for None)."""
    return t if size is None else resize(t, size, size)
