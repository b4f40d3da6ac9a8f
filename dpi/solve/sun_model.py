"""A parametric sun next to the prior's sky: the light a 32 x 64 diffusion prior cannot hold.

Outdoor light is a sky plus a sun carrying about half its energy in a few hundredths of a percent
of the sphere. A free or prior-guided map spreads that energy over a blurred blob (a diffuse
object barely tells the two apart), so `dps` can model the sun apart from the sky: a sun of
irradiance E (RGB) at map coordinates (u, v), drawn as a disc of the sun's angular size with its
aureole (dpi.light.sunlight), so that its energy is E at any map size and it stays differentiable in
(u, v). `extract_sun` moves the excess energy of a map's brightest region into such a sun; the sampler
then fits both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from dpi.io.images import luminance
from dpi.light.envmap import direction_to_uv, texel_solid_angles
from dpi.light.sunlight import SUN_RADIUS_DEG as DISC_RADIUS_DEG
from dpi.light.sunlight import direction_of_uv, draw_sun, peel_brightest


@dataclass(frozen=True)
class SunExtraction:
    """Where a map's sun is found, what it carries, and the map without it."""

    sky: torch.Tensor
    """(H, 2H, 3) the map with the sun's excess energy removed"""
    uv: torch.Tensor
    """(2,) the sun's map coordinates in [0, 1)^2 (Mitsuba's u along the azimuth, v from the top)"""
    irradiance: torch.Tensor
    """(3,) the sun's energy per channel (radiance x solid angle summed over the removed excess)"""
    share: float
    """the excess's share of the map's energy (luminance x solid angle)"""


SUN_RADIUS_DEG = 25.0
"""radius around the init's brightest texel whose excess energy becomes the sun"""


def solid_angles(height: int, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """(H, 1) texel solid angles of an H x 2H map as a tensor."""
    return torch.as_tensor(texel_solid_angles(height), dtype=dtype)


def extract_sun(env: torch.Tensor, radius_deg: float = SUN_RADIUS_DEG) -> SunExtraction:
    """The excess of the map over its surroundings within `radius_deg` of the brightest texel, as a sun
    (dpi.light.sunlight.peel_brightest); the sun sits at the energy-weighted centroid of the excess."""
    spot = peel_brightest(env, radius_deg)
    uv = torch.as_tensor(direction_to_uv(spot.direction.numpy()), dtype=env.dtype)
    return SunExtraction(spot.sky, uv, spot.irradiance, spot.share)


def sun_env(uv: torch.Tensor, irradiance: torch.Tensor, height: int,
            radius_deg: float = DISC_RADIUS_DEG) -> torch.Tensor:
    """(H, 2H, 3) map of a sun of `irradiance` (3,) at map coordinates `uv` (2,), drawn as a disc of `radius_deg`
    (the sun's own by default) with its aureole (dpi.light.sunlight): its energy is `irradiance` on any map,
    differentiable in both."""
    return draw_sun(direction_of_uv(uv), irradiance, height, radius_deg)


def sun_direction_of(uv: torch.Tensor) -> np.ndarray:
    """World direction of map coordinates (u, v) (Mitsuba's convention, as dpi.light.envmap)."""
    return direction_of_uv(torch.as_tensor(uv, dtype=torch.float64).detach()).numpy()


def map_energy(env: torch.Tensor) -> torch.Tensor:
    """(3,) energy of an (H, 2H, 3) map per channel: radiance x texel solid angle, summed."""
    return (env * solid_angles(env.shape[0], env.dtype)[..., None]).sum(dim=(0, 1))


def sun_summary(uv: torch.Tensor, irradiance: torch.Tensor, env: torch.Tensor) -> dict[str, object]:
    """The trace's record of a fitted sun: direction, irradiance, and its share of the map's energy."""
    return {"uv": [round(float(a), 5) for a in uv], "direction": [round(float(a), 5) for a in sun_direction_of(uv)],
            "irradiance": [float(a) for a in irradiance],
            "energy_share": float(luminance(irradiance) / luminance(map_energy(env)).clamp_min(1e-30))}


def wrap_uv_(uv: torch.Tensor) -> None:
    """Keep map coordinates on the map, in place: u wraps around the azimuth, v stays in [0, 1]."""
    with torch.no_grad():
        uv[0] = torch.remainder(uv[0], 1.0)
        uv[1] = uv[1].clamp(0.0, 1.0)


def share_penalty(irradiance: torch.Tensor, env: torch.Tensor, target: float) -> torch.Tensor:
    """(logit s - logit target)^2 for the sun's share s of the energy of `env` (which holds the sun):
    the data barely tell a sun from a bright patch of sky around it, so this prior sets their split."""
    share = (luminance(irradiance) / luminance(map_energy(env))).clamp(1e-6, 1 - 1e-6)
    return (torch.logit(share) - math.log(target / (1 - target))).square()
