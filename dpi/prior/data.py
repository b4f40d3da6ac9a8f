"""Env-map datasets for the prior: read HDR/LDR panoramas, resize, normalise, tone-map, augment.

Radiance convention (also stored in every checkpoint): each map L is divided by a per-map scale
s = median luminance(L) / median_target, so its median luminance becomes `median_target`
(`MEDIAN_TARGETS`, per family), then mapped to [-1, 1] by the family's tone curve
x = 2 a (L / s)^(1/gamma) - 1. Going back, `ToneCurve.with_scale(s).to_radiance(x)` gives HDR
radiance for any chosen scene scale s. Augmentation is the paper's: a random horizontal roll
(rotation about the up axis) and a random horizontal flip.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch.nn import functional as F

from dpi.images import IMAGE_SUFFIXES, luminance, read_image
from dpi.tonecurve import TONE_CURVES, ToneCurve

PANORAMA_SUFFIXES = IMAGE_SUFFIXES + (".hdr",)
MEDIAN_TARGETS = {"outdoor": 0.3, "indoor": 0.05}


def read_panorama(path: str | Path) -> np.ndarray:
    """Linear float32 (h, w, 3) from .exr/.png/.jpg (via dpi.images) or Radiance .hdr (via Mitsuba's Bitmap)."""
    path = Path(path)
    if path.suffix.lower() != ".hdr":
        return read_image(path)
    from dpi import backend

    mi = backend.mitsuba()
    bitmap = mi.Bitmap(str(path)).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, srgb_gamma=False)
    image = np.array(bitmap, dtype=np.float32)
    if not np.isfinite(image).all() or (image < 0).any():
        raise ValueError(f"{path}: HDR image contains NaN/Inf or negative values")
    return image


def resize_area(image: torch.Tensor, height: int) -> torch.Tensor:
    """Area-resample (C, h, w) to (C, height, 2 height): each output texel averages the input texels it covers."""
    return F.interpolate(image[None], size=(height, 2 * height), mode="area")[0]


def radiance_scale(radiance: torch.Tensor, median_target: float) -> float:
    """Per-map scale s with median luminance(radiance / s) = median_target; radiance is (3, H, W)."""
    lum = luminance(radiance.permute(1, 2, 0))
    median = float(lum.median())
    return max(median, 1e-8) / median_target


def to_prior_space(radiance: torch.Tensor, family: str) -> torch.Tensor:
    """(3, H, W) HDR radiance -> (3, H, W) prior image in [-1, 1] under the family's convention."""
    scale = radiance_scale(radiance, MEDIAN_TARGETS[family])
    return TONE_CURVES[family].with_scale(scale).to_prior(radiance)


def prior_tone_curve(family: str, scale: float = 1.0) -> ToneCurve:
    """The family's tone curve with radiance scale `scale` (1.0: the training normalisation)."""
    return TONE_CURVES[family].with_scale(scale)


def list_panoramas(folder: str | Path) -> list[Path]:
    """Sorted panorama files (.exr/.hdr/.png/.jpg) directly inside `folder`."""
    files = sorted(p for p in Path(folder).iterdir() if p.suffix.lower() in PANORAMA_SUFFIXES)
    if not files:
        raise FileNotFoundError(f"{folder}: no panoramas ({', '.join(PANORAMA_SUFFIXES)})")
    return files


def roll_columns(x: torch.Tensor, shifts: torch.Tensor) -> torch.Tensor:
    """Roll each image of (B, C, H, W) by its own column shift (B,): out[..., c] = x[..., (c - shift) mod W]."""
    width = x.shape[-1]
    cols = (torch.arange(width, device=x.device)[None] - shifts[:, None]) % width
    return torch.gather(x, -1, cols[:, None, None, :].expand_as(x))


def augment(x: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
    """Random per-image azimuth roll and horizontal flip of a batch (B, C, H, W) (paper's augmentation)."""
    b, width = x.shape[0], x.shape[-1]
    shifts = torch.randint(0, width, (b,), generator=generator).to(x.device)
    flips = (torch.rand(b, generator=generator) < 0.5).to(x.device)
    x = torch.where(flips[:, None, None, None], x.flip(-1), x)
    return roll_columns(x, shifts)


class EnvmapDataset:
    """All panoramas of a folder in prior space, held in memory as one (N, 3, H, 2H) tensor."""

    def __init__(self, folder: str | Path, height: int, family: str, files: list[Path] | None = None):
        self.family = family
        self.height = height
        self.files = files if files is not None else list_panoramas(folder)
        images = [resize_area(torch.from_numpy(read_panorama(p)).permute(2, 0, 1), height) for p in self.files]
        self.images = torch.stack([to_prior_space(im, family) for im in images])

    def __len__(self) -> int:
        return len(self.images)

    def batch(self, size: int, generator: torch.Generator | None = None) -> torch.Tensor:
        """A random augmented batch (size, 3, H, 2H) in [-1, 1], drawn with replacement."""
        idx = torch.randint(0, len(self.images), (size,), generator=generator)
        return augment(self.images[idx], generator)


def split_files(files: list[Path], held_out_fraction: float, seed: int = 0) -> tuple[list[Path], list[Path]]:
    """Deterministic (train, held-out) split of a file list."""
    order = np.random.default_rng(seed).permutation(len(files))
    n_held = int(round(held_out_fraction * len(files)))
    held = sorted(files[i] for i in order[:n_held])
    return sorted(files[i] for i in order[n_held:]), held
