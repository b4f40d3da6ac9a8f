"""How real a set of env maps looks, judged against real panoramas, with no pretrained network.

Each map is brought to a common footing: area-resampled to REALISM_HEIGHT rows, divided by its median luminance
(a map's exposure says nothing of its realism) and taken to log radiance, capped at LOG_CEILING (a sun's or a
lamp's energy is judged elsewhere; here it would drown the rest in the distance's tails). Patches of PATCH x PATCH
texels are then cut at two scales (the map and its 2x coarser copy) and described by their mean colour, their
texture (texels less the mean, weighted TEXTURE_WEIGHT) and their elevation (a sun belongs in the sky, a road
below the horizon). The distance between two sets is the sliced Wasserstein distance between their patch clouds:
the mean over fixed random directions of the L2 distance between the two sorted projections (quantile functions).
It is 0 for two sets of the same maps, symmetric, and grows as the patches' statistics part: a procedural world's
flat facades and uniform skies show where a real panorama's clutter does not."""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import torch
from torch.nn import functional as F

from dpi.evaluation.metrics import missing
from dpi.io.images import luminance
from dpi.prior.data import list_panoramas, read_panorama, resize_map

REALISM_HEIGHT = 32
"""rows every map is resampled to before its patches are cut"""
PATCH = 4
"""patch side, in texels"""
LOG_FLOOR = 1e-4
"""radiance floor (in medians) before the logarithm: black texels do not run to -inf"""
LOG_CEILING = 5.0
"""log-radiance cap (e^5 ~ 150 medians)"""
TEXTURE_WEIGHT = 3.0
"""weight of a patch's texture and elevation beside its mean colour: a procedural world's flat facades and even
skies differ from real clutter in texture more than in colour"""


@dataclass(frozen=True)
class RealismConfig:
    """The sliced Wasserstein distance's fixed draws."""

    projections: int = 256
    """random unit directions the patch clouds are projected on"""
    quantiles: int = 512
    """points of each projected quantile function compared"""
    seed: int = 0
    """seed of the directions (the same for every comparison, so distances compare)"""


def log_map(env: np.ndarray, height: int = REALISM_HEIGHT) -> torch.Tensor:
    """(3, height, 2 height) log radiance of an HDR map (H, W, 3), its median luminance brought to 1."""
    x = resize_map(torch.from_numpy(np.ascontiguousarray(env, dtype=np.float32)).permute(2, 0, 1).clamp_min(0), height)
    median = float(luminance(x.permute(1, 2, 0)).median())
    return torch.log(x / max(median, 1e-12) + LOG_FLOOR).clamp(max=LOG_CEILING)


def patches(env: np.ndarray) -> torch.Tensor:
    """(N, 3 + 3 PATCH^2 + 1) patch descriptors of one map at two scales: the patch's mean log radiance per channel,
    its texels less that mean and its elevation (cos of its centre's polar angle), the last two TEXTURE_WEIGHTed."""
    out = []
    for height in (REALISM_HEIGHT, REALISM_HEIGHT // 2):
        x = log_map(env, height)
        cols = F.unfold(x[None], PATCH, stride=PATCH // 2)[0].T.reshape(-1, 3, PATCH * PATCH)  # (N, 3, PATCH^2)
        mean = cols.mean(-1)
        rows = (height - PATCH) // (PATCH // 2) + 1
        centre = (torch.arange(rows) * (PATCH // 2) + PATCH / 2) / height * np.pi
        elevation = torch.cos(centre).repeat_interleave(cols.shape[0] // rows)[:, None]
        texture = (cols - mean[..., None]).flatten(1)
        out.append(torch.cat([mean, TEXTURE_WEIGHT * texture, TEXTURE_WEIGHT * elevation], dim=1))
    return torch.cat(out)


def sliced_wasserstein(a: torch.Tensor, b: torch.Tensor, cfg: RealismConfig = RealismConfig()) -> float:
    """Sliced Wasserstein-2 distance between point clouds a (N, D) and b (M, D): the root mean square over random
    unit directions of the L2 distance between the two projections' quantile functions."""
    generator = torch.Generator().manual_seed(cfg.seed)
    directions = torch.randn(a.shape[1], cfg.projections, generator=generator, dtype=torch.float64)
    directions /= directions.norm(dim=0, keepdim=True)
    levels = (torch.arange(cfg.quantiles, dtype=torch.float64) + 0.5) / cfg.quantiles
    qa = torch.quantile(a.double() @ directions, levels, dim=0)
    qb = torch.quantile(b.double() @ directions, levels, dim=0)
    return float(((qa - qb) ** 2).mean().sqrt())


def realism_distance(maps: list[np.ndarray], references: list[np.ndarray],
                     cfg: RealismConfig = RealismConfig()) -> float:
    """Distance of a set of HDR maps to a set of real reference panoramas (lower: more like them)."""
    if not maps or not references:
        raise ValueError("realism_distance needs at least one map and one reference")
    return sliced_wasserstein(torch.cat([patches(m) for m in maps]), torch.cat([patches(r) for r in references]), cfg)


@lru_cache(maxsize=4)
def reference_patches(folder: str) -> torch.Tensor:
    """The patch cloud of every panorama in `folder` (read once a process)."""
    return torch.cat([patches(read_panorama(path)) for path in list_panoramas(folder)])


def env_realism(env: np.ndarray, references: str | Path | None, cfg: RealismConfig = RealismConfig()) -> float | str:
    """One sample's realism distance to the panoramas of the folder `references` (config
    evaluate.reference_panoramas), or the missing-value saying none were given."""
    if references is None:
        return missing("no evaluate.reference_panoramas")
    return sliced_wasserstein(patches(env), reference_patches(str(Path(references).resolve())), cfg)
