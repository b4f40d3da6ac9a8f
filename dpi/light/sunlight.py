"""The sun's image on an equirectangular map, and the bright spots a map holds.

A sun is drawn as what it is: a disc of the sun's angular size, anti-aliased over one texel so that it
moves smoothly between texel centres (its direction stays differentiable), and a faint circumsolar
aureole around it; both are normalised on the map itself, so the drawn energy is the given irradiance
exactly at any resolution. Procedural daylight, the `dps` sampler and the written maps all draw it
here. `find_spots` peels the sun-like spots (far brighter than their surroundings) off a map with their
energy, so a sampler can merge a second sun into its fitted one and a test or a report can count them.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import torch

from dpi.io.images import luminance
from dpi.light.envmap import texel_directions, texel_solid_angles

SUN_RADIUS_DEG = 0.2665
"""half the sun's mean angular diameter as seen from the Earth (0.533 deg)"""
AUREOLE_SHARE = 0.05
"""share of a drawn sun's energy in its aureole (clear skies scatter a few percent of the direct
sunlight within a few degrees of the disc)"""
AUREOLE_DEG = 2.0
"""e-folding angle of the aureole's radiance away from the disc"""
AUREOLE_EXTENT_DEG = 12.0
"""angle from the sun's centre beyond which the aureole is zero"""
SPOT_CONTRAST = 6.0
"""a sun-like spot's peak stands at least this many times above the level of its surroundings (a cloud's
edge or a bright horizon stands two or three times above theirs)"""
SPOT_RADIUS_DEG = 10.0
"""radius around a spot's peak whose excess over the surroundings (the ring out to twice it) is the spot"""


@functools.lru_cache(maxsize=8)
def _texel_directions(height: int) -> torch.Tensor:
    return torch.as_tensor(texel_directions(height), dtype=torch.float64)


def _angles_to(direction: torch.Tensor, height: int) -> torch.Tensor:
    """(H, 2H) angle in radians between every texel centre and unit `direction` (3,), through the chord
    (well-conditioned near zero, where acos is not)."""
    dirs = _texel_directions(height).to(direction.dtype)
    chord = ((dirs - direction).square().sum(-1) + 1e-20).sqrt()
    return 2 * torch.asin((chord / 2).clamp(max=1.0))


def sun_weights(direction: torch.Tensor, height: int, radius_deg: float = SUN_RADIUS_DEG) -> torch.Tensor:
    """(H, 2H) radiance per unit irradiance of a sun towards unit `direction` (3,) on an H x 2H map: the
    disc (radius `radius_deg`, the sun's own by default, its edge spread over one texel) and the aureole, each
    normalised so that weights x texel solid angles sum to its share of 1."""
    angle = _angles_to(direction, height)
    texel = math.pi / height
    radius = math.radians(radius_deg)
    disc = ((radius + texel - angle) / texel).clamp(0.0, 1.0)
    extent = max(math.radians(AUREOLE_EXTENT_DEG), 1.5 * texel)  # on a coarse map: at least the nearest texels
    aureole = torch.exp(-angle / math.radians(AUREOLE_DEG)) * (angle <= extent)
    omega = torch.as_tensor(texel_solid_angles(height), dtype=direction.dtype)
    disc = disc / (disc * omega).sum()
    aureole = aureole / (aureole * omega).sum()
    return (1 - AUREOLE_SHARE) * disc + AUREOLE_SHARE * aureole


def draw_sun(direction: torch.Tensor, irradiance: torch.Tensor, height: int,
             radius_deg: float = SUN_RADIUS_DEG) -> torch.Tensor:
    """(H, 2H, 3) map of a sun of `irradiance` (3,) towards unit `direction` (3,) as a disc of `radius_deg`: its
    energy (radiance x solid angle, summed) is `irradiance`; differentiable in both."""
    return sun_weights(direction, height, radius_deg)[..., None] * irradiance


def draw_sun_np(direction: np.ndarray, irradiance: np.ndarray, height: int) -> np.ndarray:
    """`draw_sun` on numpy arrays (float64)."""
    return draw_sun(torch.as_tensor(direction, dtype=torch.float64),
                    torch.as_tensor(irradiance, dtype=torch.float64), height).numpy()


@dataclass(frozen=True)
class Spot:
    """A map's brightest region peeled off it: its excess over its surroundings, as a sun would be."""

    sky: torch.Tensor
    """(H, 2H, 3) the map without the excess"""
    irradiance: torch.Tensor
    """(3,) the excess's energy per channel (radiance x solid angle, summed)"""
    direction: torch.Tensor
    """(3,) unit direction of the excess's energy-weighted centre"""
    share: float
    """the excess's share of the map's energy (luminance)"""
    contrast: float
    """the peak texel's luminance over the surroundings' level"""


def peel_brightest(env: torch.Tensor, radius_deg: float) -> Spot:
    """The excess of a map (H, 2H, 3) over its surroundings within `radius_deg` of its brightest texel: the
    surroundings' level is the per-channel median of the ring radius..2 radius; texels within half the radius
    keep at most that level, and the removal fades out towards the radius (no visible edge where it stops)."""
    height = env.shape[0]
    env = env.detach()
    lum = luminance(env)
    dirs = _texel_directions(height).to(env.dtype)
    peak_index = int(torch.argmax(lum))
    peak = dirs.reshape(-1, 3)[peak_index]
    cos = dirs @ peak
    inner = cos >= math.cos(math.radians(radius_deg))
    ring = ~inner & (cos >= math.cos(math.radians(2 * radius_deg)))
    level = env[ring].median(dim=0).values if bool(ring.any()) else env.reshape(-1, 3).median(dim=0).values
    angle = torch.acos(cos.clamp(-1.0, 1.0))
    window = ((math.radians(radius_deg) - angle) / math.radians(radius_deg / 2)).clamp(0.0, 1.0)
    excess = window[..., None] * (env - level).clamp_min(0)
    omega = torch.as_tensor(texel_solid_angles(height), dtype=env.dtype)[..., None]
    weight = luminance(excess) * omega[..., 0]
    centre = (weight[..., None] * dirs).sum(dim=(0, 1))
    centre = centre / centre.norm() if float(centre.norm()) > 0 else peak
    share = float(weight.sum() / (lum * omega[..., 0]).sum().clamp_min(1e-30))
    contrast = float(lum.reshape(-1)[peak_index] / luminance(level).clamp_min(1e-30))
    return Spot(env - excess, (excess * omega).sum(dim=(0, 1)), centre, share, contrast)


def find_spots(env: torch.Tensor, contrast: float = SPOT_CONTRAST, radius_deg: float = SPOT_RADIUS_DEG,
               limit: int = 8) -> list[Spot]:
    """The sun-like spots of a map (H, 2H, 3), brightest first: its brightest texel is peeled off
    (`peel_brightest`) while it stands `contrast` times above its surroundings, at most `limit` times; each
    spot's `sky` is the map with it and those before it removed."""
    spots: list[Spot] = []
    sky = env.detach()
    while len(spots) < limit:
        spot = peel_brightest(sky, radius_deg)
        if spot.contrast < contrast or spot.share <= 0:
            break
        spots.append(spot)
        sky = spot.sky
    return spots


def merge_spots_into_sun(sky: torch.Tensor, irradiance: torch.Tensor, detail_height: int,
                         contrast: float = SPOT_CONTRAST) -> tuple[torch.Tensor, torch.Tensor, int]:
    """The sun-like spots of a sky map (H, 2H, 3) (a sun the prior drew, say) moved into a sun of `irradiance`:
    each spot's excess leaves the sky and its energy joins the sun's, so the map's energy is kept and one sun
    remains. The sky's detail is that of a `detail_height`-row map (upsampled): a spot is taken at least two of
    its texels wide. Returns the sky, the sun's irradiance and the number of spots merged."""
    spots = find_spots(sky, contrast, max(SPOT_RADIUS_DEG, 360.0 / detail_height))
    if not spots:
        return sky, irradiance, 0
    energy = sum(s.irradiance for s in spots)
    return spots[-1].sky, irradiance + energy.to(irradiance.dtype), len(spots)


def direction_of_uv(uv: torch.Tensor) -> torch.Tensor:
    """Unit world direction (3,) of map coordinates (u, v), differentiable (Mitsuba's convention, dpi.light.envmap)."""
    phi, theta = 2 * math.pi * uv[0], math.pi * uv[1]
    return torch.stack([torch.sin(phi) * torch.sin(theta), torch.cos(theta), -torch.cos(phi) * torch.sin(theta)])
