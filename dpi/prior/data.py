"""Env-map datasets for the prior: read HDR/LDR panoramas, resize, normalise, encode, augment.

Radiance convention (also stored in every checkpoint): each map L is divided by a per-map scale
s = median luminance(L) / median_target, so its median luminance becomes `median_target`, then
mapped to [-1, 1] by the prior's encoding (dpi.light.tonecurve): log radiance (median_target 1), or the
paper's tone curve x = 2 a (L / s)^(1/gamma) - 1 (median_target per family, `MEDIAN_TARGETS`).
Going back, `encoding.with_scale(s).to_radiance(x)` gives HDR radiance for any chosen scene
scale s. Augmentation is the paper's, a random horizontal roll (rotation about the up axis) and a
random horizontal flip, plus a small random tilt of the up axis (a panorama's camera is never exactly
level) and a random exposure and white balance (real panoramas' are arbitrary). A
dataset can be packed into one `.npz` (x quantised to 8 bits, with its encoding) to train elsewhere,
e.g. on a GPU machine without the generators.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch
from torch.nn import functional as F

from dpi.io.atomic import atomic_path
from dpi.io.exr import read_exr
from dpi.io.images import HDR_SUFFIXES, IMAGE_SUFFIXES, luminance, read_hdr, read_image
from dpi.light.envmap import direction_to_uv, pad_equirect, texel_directions
from dpi.light.tonecurve import Encoding, encoding_from_dict

PANORAMA_SUFFIXES = IMAGE_SUFFIXES + (".hdr",)
NEGATIVE_TOLERANCE = 0.1
"""a panorama's negative texels above -this x its median luminance are out-of-gamut noise, clamped to 0"""
MEDIAN_TARGETS = {"outdoor": 0.3, "indoor": 0.05}
"""median luminance of a training map under the paper's tone curves (the log encoding uses 1)"""
PACK_LEVELS = 255
"""a packed dataset stores x in [-1, 1] as round((x + 1) / 2 * PACK_LEVELS) in uint8"""
EXPOSURE_JITTER = 0.3
"""std of the log exposure a training batch's maps are scaled by (`recolour`)"""
WHITE_BALANCE_JITTER = 0.08
"""std of the log per-channel gains of a training batch's white balance (`recolour`)"""
MAX_TILT_DEG = 4.0
"""largest tilt of the up axis a training map is given (`tilt`), drawn uniformly in [-max, max]"""


def read_panorama(path: str | Path) -> np.ndarray:
    """Linear float32 (h, w, 3) from .exr/.png/.jpg or Radiance .hdr. Slight negatives
    (a colour-space conversion's out-of-gamut texels, above -NEGATIVE_TOLERANCE x the median luminance) are
    clamped to 0; NaN/Inf or larger negatives are errors naming the file."""
    path = Path(path)
    if path.suffix.lower() in HDR_SUFFIXES:
        image = read_exr(path)[..., :3]
        image = np.repeat(image, 3, axis=-1) if image.shape[-1] == 1 else image
    elif path.suffix.lower() == ".hdr":
        image = read_hdr(path)
    else:
        return read_image(path)
    if not np.isfinite(image).all():
        raise ValueError(f"{path}: HDR image contains NaN/Inf values")
    floor = -NEGATIVE_TOLERANCE * float(np.median(luminance(np.maximum(image, 0))))
    if image.min() < floor:
        raise ValueError(f"{path}: HDR image has negative values down to {image.min():.3g} "
                         f"(more than {NEGATIVE_TOLERANCE:.0%} of its median luminance)")
    return np.maximum(image, 0).astype(np.float32)


def resize_map(image: torch.Tensor, height: int) -> torch.Tensor:
    """Area-resample (C, h, w) to (C, height, 2 height): each output texel averages the input texels it covers."""
    return F.interpolate(image[None], size=(height, 2 * height), mode="area")[0]


def radiance_scale(radiance: torch.Tensor, median_target: float) -> float:
    """Per-map scale s with median luminance(radiance / s) = median_target; radiance is (3, H, W)."""
    lum = luminance(radiance.permute(1, 2, 0))
    median = float(lum.median())
    return max(median, 1e-8) / median_target


def median_target(family: str, encoding: Encoding) -> float:
    """Median luminance of a normalised training map: 1 in log radiance, the family's under the paper's curve."""
    return MEDIAN_TARGETS[family] if encoding.to_dict()["kind"] == "power" else 1.0


def to_prior_space(radiance: torch.Tensor, encoding: Encoding, target: float) -> torch.Tensor:
    """(3, H, W) HDR radiance -> (3, H, W) prior image in [-1, 1], normalised to median luminance `target`."""
    return encoding.with_scale(radiance_scale(radiance, target)).to_prior(radiance)


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


def clip_highlights(x: torch.Tensor, encoding: Encoding, median: float, fraction: float,
                    multiples: tuple[float, float], generator: torch.Generator | None = None) -> torch.Tensor:
    """A random `fraction` of a batch (B, 3, H, W) of prior-space maps (median luminance `median` at the
    encoding's scale 1) with their luminance clipped at a multiple of the median drawn log-uniformly from
    `multiples`, hue kept: what an 8-bit panorama decoded to linear looks like (the paper's outdoor data
    were such panoramas)."""
    b = x.shape[0]
    chosen = torch.rand(b, generator=generator, device=x.device) < fraction
    lo, hi = (math.log(m) for m in multiples)
    level = median * torch.exp(lo + (hi - lo) * torch.rand(b, generator=generator, device=x.device))
    radiance = encoding.with_scale(1.0).to_radiance(x)
    lum = luminance(radiance.movedim(1, -1)).unsqueeze(1)
    factor = (level[:, None, None, None] / lum.clamp_min(1e-12)).clamp(max=1.0)
    return torch.where(chosen[:, None, None, None], encoding.with_scale(1.0).to_prior(radiance * factor), x)


def augment(x: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
    """Random per-image azimuth roll and horizontal flip of a batch (B, C, H, W) (paper's augmentation)."""
    b, width = x.shape[0], x.shape[-1]
    shifts = torch.randint(0, width, (b,), generator=generator, device=x.device)
    flips = torch.rand(b, generator=generator, device=x.device) < 0.5
    x = torch.where(flips[:, None, None, None], x.flip(-1), x)
    return roll_columns(x, shifts)


def tilt(x: torch.Tensor, degrees: torch.Tensor) -> torch.Tensor:
    """Each map of a batch (B, C, H, 2H) rotated by its own angle `degrees` (B,) about the horizontal axis
    +X, resampled bilinearly across the seam and the poles: a camera held a little off level."""
    b, _, height, width = x.shape
    angle = np.deg2rad(degrees.detach().cpu().numpy().astype(np.float64))[:, None, None]
    d = texel_directions(height)[None]
    cos, sin = np.cos(angle), np.sin(angle)
    # the source of each output texel: R^T d, with R the rotation by `angle` about +X
    source = np.stack([np.broadcast_to(d[..., 0], (b, height, width)),
                       cos * d[..., 1] + sin * d[..., 2], -sin * d[..., 1] + cos * d[..., 2]], axis=-1)
    uv = direction_to_uv(source)
    # grid_sample on the map padded by one texel on every side (pad_equirect), align_corners=False
    gx = (uv[..., 0] * width + 1.0) / (width + 2) * 2.0 - 1.0
    gy = (uv[..., 1] * height + 1.0) / (height + 2) * 2.0 - 1.0
    grid = torch.from_numpy(np.stack([gx, gy], axis=-1).astype(np.float32)).to(x.device)
    return F.grid_sample(pad_equirect(x, 1), grid, mode="bilinear", padding_mode="border", align_corners=False)


def recolour(x: torch.Tensor, encoding: Encoding, generator: torch.Generator | None = None) -> torch.Tensor:
    """Random per-image exposure (log-normal, std EXPOSURE_JITTER) and white balance (per-channel log-normal
    gains, std WHITE_BALANCE_JITTER, luminance kept) of a batch (B, 3, H, W) of prior-space maps: a real
    panorama's exposure and camera white balance are arbitrary, its content is not."""
    b = x.shape[0]
    exposure = EXPOSURE_JITTER * torch.randn(b, 1, generator=generator, device=x.device)
    tint = torch.exp(WHITE_BALANCE_JITTER * torch.randn(b, 3, generator=generator, device=x.device))
    tint = tint / luminance(tint)[:, None]
    gain = (torch.exp(exposure) * tint)[..., None, None]
    unit = encoding.with_scale(1.0)
    return unit.to_prior(unit.to_radiance(x) * gain)


class EnvmapDataset:
    """Env maps in prior space, held in memory as one (N, 3, H, 2H) tensor (on any device).

    `quantum` is the step of a packed (8-bit) dataset: batches add uniform noise of that width, so the
    network sees a continuous density rather than 256 levels."""

    def __init__(self, images: torch.Tensor, family: str, encoding: Encoding, quantum: float = 0.0,
                 weights: torch.Tensor | None = None):
        self.images = images
        self.family = family
        self.encoding = encoding
        self.height = images.shape[-2]
        self.quantum = quantum
        self.weights = weights
        """per-map sampling weights of `batch` (None: uniform)"""

    @classmethod
    def mixed(cls, parts: list["EnvmapDataset"], fractions: list[float]) -> "EnvmapDataset":
        """One dataset whose batches draw a `fractions[i]` share of their maps from `parts[i]` (e.g. real
        panoramas beside procedural worlds); the parts must share height, family and encoding."""
        first = parts[0]
        for part in parts[1:]:
            if (part.height, part.family, part.encoding.to_dict()) != (first.height, first.family,
                                                                       first.encoding.to_dict()):
                raise ValueError("mixed datasets differ in height, family or encoding")
        if len(fractions) != len(parts) or min(fractions) < 0 or sum(fractions) <= 0:
            raise ValueError(f"need one non-negative fraction per dataset, got {fractions}")
        weights = torch.cat([torch.full((len(p),), f / len(p)) for p, f in zip(parts, fractions)])
        return cls(torch.cat([p.images.cpu() for p in parts]), first.family, first.encoding,
                   max(p.quantum for p in parts), weights)

    @classmethod
    def from_folder(cls, folder: str | Path, height: int, family: str, encoding: Encoding,
                    files: list[Path] | None = None) -> "EnvmapDataset":
        """All panoramas of a folder (or the given `files`), area-resampled to `height`, normalised and encoded."""
        target = median_target(family, encoding)
        paths = files if files is not None else list_panoramas(folder)
        images = [resize_map(torch.from_numpy(read_panorama(p)).permute(2, 0, 1), height) for p in paths]
        return cls(torch.stack([to_prior_space(im, encoding, target) for im in images]), family, encoding)

    @classmethod
    def load(cls, path: str | Path) -> "EnvmapDataset":
        """A dataset packed by `save` (one .npz file)."""
        with np.load(path) as packed:
            x = torch.from_numpy(packed["x"].astype(np.float32)) * (2.0 / PACK_LEVELS) - 1.0
            meta = {"family": str(packed["family"]), "encoding": encoding_from_dict(
                {k[len("encoding_"):]: packed[k].item() for k in packed.files if k.startswith("encoding_")})}
        return cls(x, meta["family"], meta["encoding"], quantum=2.0 / PACK_LEVELS)

    def save(self, path: str | Path) -> None:
        """Pack the maps into one compressed .npz: x in 8 bits, the family and the encoding's parameters."""
        levels = ((self.images.cpu().clamp(-1, 1) + 1) / 2 * PACK_LEVELS).round().to(torch.uint8).numpy()
        encoding = {f"encoding_{k}": np.array(v) for k, v in self.encoding.to_dict().items()}
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as handle:
                np.savez_compressed(handle, x=levels, family=np.array(self.family), **encoding)

    def to(self, device: str | torch.device) -> "EnvmapDataset":
        """The same dataset with its maps on `device` (train where the network is)."""
        weights = None if self.weights is None else self.weights.to(device)
        return EnvmapDataset(self.images.to(device), self.family, self.encoding, self.quantum, weights)

    def __len__(self) -> int:
        return len(self.images)

    def batch(self, size: int, generator: torch.Generator | None = None) -> torch.Tensor:
        """A random augmented batch (size, 3, H, 2H) in [-1, 1], drawn with replacement (`generator` on
        the maps' device)."""
        device = self.images.device
        if self.weights is None:
            idx = torch.randint(0, len(self.images), (size,), generator=generator, device=device)
        else:
            idx = torch.multinomial(self.weights, size, replacement=True, generator=generator)
        angles = MAX_TILT_DEG * (2.0 * torch.rand(size, generator=generator, device=device) - 1.0)
        x = recolour(augment(tilt(self.images[idx], angles), generator), self.encoding, generator)
        if self.quantum:
            x = (x + self.quantum * (torch.rand(x.shape, generator=generator, device=device) - 0.5)).clamp(-1, 1)
        return x


def read_dataset(path: str | Path, height: int, family: str, encoding: Encoding) -> EnvmapDataset:
    """A folder of panoramas (resampled, normalised and encoded now) or a packed .npz, which must match."""
    if Path(path).is_dir():
        return EnvmapDataset.from_folder(path, height, family, encoding)
    data = EnvmapDataset.load(path)
    found = (data.height, data.family, data.encoding.to_dict())
    if found != (height, family, encoding.to_dict()):
        raise ValueError(f"{path}: packed dataset has (height, family, encoding) {found}, "
                         f"expected {(height, family, encoding.to_dict())}")
    return data


def split_files(files: list[Path], held_out_fraction: float, seed: int = 0) -> tuple[list[Path], list[Path]]:
    """Deterministic (train, held-out) split of a file list."""
    order = np.random.default_rng(seed).permutation(len(files))
    n_held = int(round(held_out_fraction * len(files)))
    held = sorted(files[i] for i in order[:n_held])
    return sorted(files[i] for i in order[n_held:]), held
