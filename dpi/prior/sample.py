"""Loading a trained prior and drawing unconditional env maps from it (EXR files and PNG grids)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from PIL import Image

from dpi.capture import PRIORS
from dpi.io.atomic import atomic_path, write_json
from dpi.io.exr import write_exr
from dpi.io.layout import package_data
from dpi.light.tonecurve import Encoding, encoding_from_dict
from dpi.prior.diffusion import Diffusion, base_diffusion, evenly_spaced_timesteps, respaced, sample
from dpi.prior.unet import UNetModel, load_checkpoint

MODELS_DIR = package_data("models")
"""the shipped priors (and their training logs), inside the package"""
DEFAULT_MODELS = {family: MODELS_DIR / f"{family}_32x64.pt" for family in PRIORS}
"""the shipped prior of each family"""
DEFAULT_FAMILY = "outdoor"
"""the family of a scene whose scene.yaml (or synthetic entry) names none, unless config.yaml's
illumination_prior.family says otherwise"""


@dataclass
class Prior:
    """A loaded prior: the network, its training schedule, its encoding and the map height."""

    model: UNetModel
    diffusion: Diffusion
    encoding: Encoding  # with scale 1: the training normalisation (median luminance = median_target)
    family: str
    height: int
    median_target: float

    def schedule(self, steps: int | None = None) -> Diffusion:
        """The training schedule, or a respaced one with `steps` evenly spaced steps."""
        if steps is None or steps == self.diffusion.num_timesteps:
            return self.diffusion
        return respaced(self.diffusion, evenly_spaced_timesteps(self.diffusion.num_timesteps, steps))


def load_prior(checkpoint: str | Path, device: str | torch.device = "cpu") -> Prior:
    """A `Prior` from a dpi checkpoint (EMA weights when present)."""
    meta = torch.load(checkpoint, map_location="cpu", weights_only=True)
    model = load_checkpoint(checkpoint, device=device).float()
    tone = meta["tone"]
    return Prior(model=model, diffusion=base_diffusion(meta["diffusion"]["num_timesteps"]),
                 encoding=encoding_from_dict(tone), family=meta["family"],
                 height=meta["height"], median_target=tone["median_target"])


def family_checkpoint(family: str, checkpoints: Mapping[str, str | Path]) -> Path:
    """A family's prior: its entry in `checkpoints` (config illumination_prior.checkpoints), else the shipped model."""
    return Path(checkpoints.get(family, DEFAULT_MODELS[family]))


def load_scene_prior(options: dict, checkpoint: str | Path | None = None) -> Prior:
    """The prior in `checkpoint`, else the shipped model of a scene's family (scene.yaml `prior`, else
    DEFAULT_FAMILY; the workflow and `dpi` pass the checkpoint of the configured family)."""
    return load_prior(checkpoint or DEFAULT_MODELS[options.get("prior", DEFAULT_FAMILY)])


def load_default_prior(family: str, device: str | torch.device = "cpu") -> Prior:
    """The shipped default prior of a family (a name in dpi.capture.PRIORS) from dpi/data/models/."""
    if family not in DEFAULT_MODELS:
        raise ValueError(f"no default prior for family {family!r}; use one of {sorted(DEFAULT_MODELS)}")
    return load_prior(DEFAULT_MODELS[family], device)


def to_display(x: torch.Tensor) -> np.ndarray:
    """Prior-space images (B, 3, H, W) -> uint8 (B, H, W, 3): (x + 1) / 2 is already tone-mapped."""
    return (((x.clamp(-1, 1) + 1) / 2).permute(0, 2, 3, 1).cpu().numpy() * 255 + 0.5).astype(np.uint8)


def grid_image(x: torch.Tensor, columns: int, pad: int = 2) -> np.ndarray:
    """Tile (B, 3, H, W) prior-space images into one uint8 (rows*(H+pad), columns*(W+pad), 3) grid."""
    tiles = to_display(x)
    b, h, w, _ = tiles.shape
    rows = -(-b // columns)
    grid = np.full((rows * (h + pad) - pad, columns * (w + pad) - pad, 3), 255, np.uint8)
    for i, tile in enumerate(tiles):
        r, c = divmod(i, columns)
        grid[r * (h + pad): r * (h + pad) + h, c * (w + pad): c * (w + pad) + w] = tile
    return grid


def write_grid(path: str | Path, x: torch.Tensor, columns: int = 4, zoom: int = 2) -> None:
    """Write a PNG grid of prior-space images, enlarged `zoom` times (nearest)."""
    grid = Image.fromarray(grid_image(x, columns))
    grid = grid.resize((grid.width * zoom, grid.height * zoom), Image.NEAREST)
    with atomic_path(path) as tmp:
        grid.save(tmp, format="PNG")


def draw_samples(prior: Prior, count: int, steps: int | None = 100, seed: int = 0,
                 random_roll: bool = True, batch_size: int = 16) -> torch.Tensor:
    """`count` unconditional prior-space maps (count, 3, H, 2H) in [-1, 1] with a respaced schedule."""
    device = next(prior.model.parameters()).device
    generator = torch.Generator(device=device).manual_seed(seed)
    diffusion = prior.schedule(steps)
    chunks = []
    for start in range(0, count, batch_size):
        n = min(batch_size, count - start)
        chunks.append(sample(diffusion, prior.model, (n, 3, prior.height, 2 * prior.height), generator,
                             random_roll, device).cpu())
    return torch.cat(chunks)


def sample_to_files(checkpoint: str | Path, out_dir: str | Path, count: int = 8, steps: int | None = 100,
                    seed: int = 0, random_roll: bool = True, device: str = "cpu") -> list[Path]:
    """Write `count` samples as HDR EXR (training normalisation, scale 1), a PNG grid and a JSON note."""
    prior = load_prior(checkpoint, device)
    x = draw_samples(prior, count, steps, seed, random_roll)
    out = Path(out_dir)
    paths = []
    for i, xi in enumerate(x):
        paths.append(out / f"sample_{i:03d}.exr")
        write_exr(paths[-1], prior.encoding.to_radiance(xi).permute(1, 2, 0).numpy())
    write_grid(out / "samples.png", x)
    write_json(out / "samples.json", {"checkpoint": str(checkpoint), "count": count, "steps": steps, "seed": seed,
                                      "random_roll": random_roll, "family": prior.family})
    return paths
