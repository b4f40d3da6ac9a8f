"""The sun's image on an equirectangular map, and the bright spots a map holds.

A sun is drawn as what it is: a disc of the sun's angular size, anti-aliased over one texel so that it
moves smoothly between texel centres (its direction stays differentiable), and a faint circumsolar
aureole around it; both are normalised on the map itself, so the drawn energy is the given irradiance
exactly at any resolution. Procedural daylight, the `dps` sampler and the written maps all draw it
here. `bright_spots` finds the compact regions far above a map's median (suns, lamps) with their energy,
so a sampler can merge a second sun into its fitted one and a test or a report can count them.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import torch
from scipy import ndimage

from dpi.envmap import texel_directions, texel_solid_angles
from dpi.images import luminance

SUN_RADIUS_DEG = 0.2665
"""half the sun's mean angular diameter as seen from the Earth (0.533 deg)"""
AUREOLE_SHARE = 0.05
"""share of a drawn sun's energy in its aureole (clear skies scatter a few percent of the direct
sunlight within a few degrees of the disc)"""
AUREOLE_DEG = 2.0
"""e-folding angle of the aureole's radiance away from the disc"""
AUREOLE_EXTENT_DEG = 12.0
"""angle from the sun's centre beyond which the aureole is zero"""
SUN_CONTRAST = 50.0
"""a bright spot is a region of texels above this many times the map's median luminance"""


@functools.lru_cache(maxsize=8)
def _texel_directions(height: int) -> torch.Tensor:
    return torch.as_tensor(texel_directions(height), dtype=torch.float64)


def _angles_to(direction: torch.Tensor, height: int) -> torch.Tensor:
    """(H, 2H) angle in radians between every texel centre and unit `direction` (3,), through the chord
    (well-conditioned near zero, where acos is not)."""
    dirs = _texel_directions(height).to(direction.dtype)
    chord = ((dirs - direction).square().sum(-1) + 1e-20).sqrt()
    return 2 * torch.asin((chord / 2).clamp(max=1.0))


def sun_weights(direction: torch.Tensor, height: int) -> torch.Tensor:
    """(H, 2H) radiance per unit irradiance of a sun towards unit `direction` (3,) on an H x 2H map: the
    disc (radius SUN_RADIUS_DEG, its edge spread over one texel) and the aureole, each normalised so that
    weights x texel solid angles sum to its share of 1."""
    angle = _angles_to(direction, height)
    texel = math.pi / height
    radius = math.radians(SUN_RADIUS_DEG)
    disc = ((radius + texel - angle) / texel).clamp(0.0, 1.0)
    extent = max(math.radians(AUREOLE_EXTENT_DEG), 1.5 * texel)  # on a coarse map: at least the nearest texels
    aureole = torch.exp(-angle / math.radians(AUREOLE_DEG)) * (angle <= extent)
    omega = torch.as_tensor(texel_solid_angles(height), dtype=direction.dtype)
    disc = disc / (disc * omega).sum()
    aureole = aureole / (aureole * omega).sum()
    return (1 - AUREOLE_SHARE) * disc + AUREOLE_SHARE * aureole


def draw_sun(direction: torch.Tensor, irradiance: torch.Tensor, height: int) -> torch.Tensor:
    """(H, 2H, 3) map of a sun of `irradiance` (3,) towards unit `direction` (3,): its energy (radiance x
    solid angle, summed) is `irradiance`; differentiable in both."""
    return sun_weights(direction, height)[..., None] * irradiance


def draw_sun_np(direction: np.ndarray, irradiance: np.ndarray, height: int) -> np.ndarray:
    """`draw_sun` on numpy arrays (float64)."""
    return draw_sun(torch.as_tensor(direction, dtype=torch.float64),
                    torch.as_tensor(irradiance, dtype=torch.float64), height).numpy()


@dataclass(frozen=True)
class BrightSpot:
    """A compact region of a map far above its median: a sun or a lamp."""

    mask: np.ndarray
    """(H, 2H) bool: the spot's texels"""
    excess: np.ndarray
    """(H, 2H, 3) the radiance the spot holds above its surroundings (zero outside the mask)"""
    energy: np.ndarray
    """(3,) the excess's energy per channel (radiance x solid angle)"""
    direction: np.ndarray
    """(3,) unit direction of the excess's energy-weighted centre"""
    radius_deg: float
    """angle from that centre to the spot's farthest texel centre"""
    share: float
    """the excess's share of the map's energy (luminance)"""


def _wrapped_labels(mask: np.ndarray) -> tuple[np.ndarray, int]:
    """Connected components (8-neighbour) of an (H, 2H) mask, joined across the azimuth seam."""
    labels, count = ndimage.label(mask, structure=np.ones((3, 3), dtype=bool))
    parent = list(range(count + 1))

    def root(i: int) -> int:
        while parent[i] != i:
            i = parent[i]
        return i

    rows = labels.shape[0]
    for r in range(rows):
        for dr in (-1, 0, 1):
            if 0 <= r + dr < rows:
                a, b = labels[r, -1], labels[r + dr, 0]
                if a and b:
                    parent[root(a)] = root(b)
    roots = np.array([root(i) for i in range(count + 1)])
    merged = roots[labels]
    unique = np.unique(merged[merged > 0])
    relabel = np.zeros(count + 1, dtype=int)
    relabel[unique] = np.arange(1, len(unique) + 1)
    return relabel[merged], len(unique)


def bright_spots(env: np.ndarray, contrast: float = SUN_CONTRAST, min_share: float = 0.0) -> list[BrightSpot]:
    """The regions of an (H, 2H, 3) map whose luminance exceeds `contrast` x its median, brightest first,
    each with the excess it holds over the median of the texels around it (a one-texel ring), and only
    those carrying at least `min_share` of the map's energy."""
    env = np.asarray(env, dtype=np.float64)
    height = env.shape[0]
    lum = luminance(env)
    omega = texel_solid_angles(height)
    total = max(float((lum * omega).sum()), 1e-30)
    labels, count = _wrapped_labels(lum > contrast * max(float(np.median(lum)), 1e-30))
    dirs = texel_directions(height)
    spots = []
    for k in range(1, count + 1):
        mask = labels == k
        grown = ndimage.binary_dilation(np.pad(mask, ((0, 0), (1, 1)), mode="wrap"), np.ones((3, 3), bool))
        ring = grown[:, 1:-1] & ~mask
        ring[:, 0] |= grown[:, -1] & ~mask[:, 0]
        ring[:, -1] |= grown[:, 0] & ~mask[:, -1]
        level = np.median(env[ring], axis=0) if ring.any() else np.zeros(3)
        excess = np.where(mask[..., None], np.maximum(env - level, 0.0), 0.0)
        energy = (excess * omega[..., None]).sum((0, 1))
        weight = luminance(excess) * omega
        centre = (weight[..., None] * dirs).sum((0, 1))
        centre = centre / max(np.linalg.norm(centre), 1e-30)
        radius = float(np.degrees(np.arccos(np.clip(dirs[mask] @ centre, -1.0, 1.0)).max()))
        share = float(weight.sum() / total)
        if share >= min_share:
            spots.append(BrightSpot(mask, excess, energy, centre, radius, share))
    return sorted(spots, key=lambda s: -s.share)


def merge_spots_into_sun(sky: torch.Tensor, direction: torch.Tensor, irradiance: torch.Tensor,
                         contrast: float = SUN_CONTRAST) -> tuple[torch.Tensor, torch.Tensor, int]:
    """The bright spots of a sky map (H, 2H, 3) (a sun the prior drew, say) moved into a sun towards
    `direction` of `irradiance`: each spot's excess leaves the sky and its energy joins the sun's, so the
    map's energy is kept and one sun remains. Returns the sky, the sun's irradiance and the spot count."""
    spots = bright_spots(sky.detach().double().numpy(), contrast)
    if not spots:
        return sky, irradiance, 0
    excess = torch.as_tensor(sum(s.excess for s in spots), dtype=sky.dtype)
    energy = torch.as_tensor(sum(s.energy for s in spots), dtype=irradiance.dtype)
    return sky - excess, irradiance + energy, len(spots)


def direction_of_uv(uv: torch.Tensor) -> torch.Tensor:
    """Unit world direction (3,) of map coordinates (u, v), differentiable (Mitsuba's convention, dpi.envmap)."""
    phi, theta = 2 * math.pi * uv[0], math.pi * uv[1]
    return torch.stack([torch.sin(phi) * torch.sin(theta), torch.cos(theta), -torch.cos(phi) * torch.sin(theta)])
