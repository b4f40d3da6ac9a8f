"""A decomposition: an environment map and material textures, as written by init and every method."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import torch

from dpi.io.exr import write_exr
from dpi.io.layout import ENV_FILE, SAMPLE_TRACE
from dpi.light.envmap import read_envmap
from dpi.solve.materials import MaterialTextures
from dpi.solve.trace import Trace


@dataclass
class Decomposition:
    """Env map (linear radiance, (H, 2H, 3)), materials, and the trace of the run that made them."""

    env: torch.Tensor
    materials: MaterialTextures
    trace: Trace | None = field(default=None, repr=False)

    def scaled(self, factor: float) -> "Decomposition":
        """The same decomposition with the env map's radiance times `factor` (materials are scale-free)."""
        return Decomposition(self.env * factor, self.materials, self.trace)

    def save(self, folder: str | Path, trace_name: str = SAMPLE_TRACE) -> None:
        """Write envmap.exr, albedo/roughness/metallic.exr and the trace into `folder`."""
        folder = Path(folder)
        if not torch.isfinite(self.env).all():
            raise ValueError(f"{folder}: refusing to save a non-finite environment map")
        write_exr(folder / ENV_FILE, self.env.detach().numpy())
        self.materials.save(folder)
        if self.trace is not None:
            self.trace.save(folder / trace_name)

    @classmethod
    def load(cls, folder: str | Path, texture_size: int | None = None) -> "Decomposition":
        """Read a decomposition folder (the trace is not read back)."""
        env = torch.from_numpy(read_envmap(Path(folder) / ENV_FILE))
        return cls(env, MaterialTextures.load(folder, texture_size))
