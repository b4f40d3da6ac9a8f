"""A parametric sun next to the prior's sky: the light a 32 x 64 diffusion prior cannot hold.

Outdoor light is a sky plus a sun carrying about half its energy in a few hundredths of a percent
of the sphere. A free or prior-guided map spreads that energy over a blurred blob (a diffuse
object barely tells the two apart), so `dps` can model the sun apart from the sky: a point of
irradiance E (RGB) at map coordinates (u, v), splatted bilinearly onto the texels of the scene map
so that its energy is E wherever it sits (and differentiable in u, v). `extract_sun` moves the
excess energy of a map's brightest region into such a sun; the sampler then fits both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from dpi.envmap import direction_to_uv, directions_from_angles, texel_directions, texel_solid_angles
from dpi.images import luminance


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


def solid_angles(height: int, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """(H, 1) texel solid angles of an H x 2H map as a tensor."""
    return torch.as_tensor(texel_solid_angles(height), dtype=dtype)


def extract_sun(env: torch.Tensor, radius_deg: float = 25.0) -> SunExtraction:
    """The excess of the map over its surroundings within `radius_deg` of the brightest texel, as a sun.

    The surroundings' level is the per-channel median of the ring radius..2 radius; texels inside the
    radius keep at most that level, and what they lose is the sun's irradiance. The sun sits at the
    energy-weighted centroid of the excess."""
    height = env.shape[0]
    env = env.detach()
    lum = luminance(env)
    dirs = torch.as_tensor(texel_directions(height), dtype=env.dtype)
    peak = dirs.reshape(-1, 3)[int(torch.argmax(lum))]
    cos = dirs @ peak
    inner = cos >= math.cos(math.radians(radius_deg))
    ring = ~inner & (cos >= math.cos(math.radians(2 * radius_deg)))
    level = env[ring].median(dim=0).values if bool(ring.any()) else env.reshape(-1, 3).median(dim=0).values
    excess = torch.where(inner[..., None], (env - level).clamp_min(0), torch.zeros_like(env))
    omega = solid_angles(height, env.dtype)[..., None]
    irradiance = (excess * omega).sum(dim=(0, 1))
    weight = luminance(excess) * omega[..., 0]
    centre = (weight[..., None] * dirs).sum(dim=(0, 1))
    centre = centre / centre.norm() if float(centre.norm()) > 0 else peak
    uv = torch.as_tensor(direction_to_uv(centre.numpy()), dtype=env.dtype)
    share = float(weight.sum() / (lum * omega[..., 0]).sum().clamp_min(1e-30))
    return SunExtraction(env - excess, uv, irradiance, share)


def sun_env(uv: torch.Tensor, irradiance: torch.Tensor, height: int, splat_height: int | None = None) -> torch.Tensor:
    """(H, 2H, 3) map of a sun of `irradiance` (3,) at `uv` (2,): bilinear weights on the four nearest
    texel centres (wrapping in azimuth, clamped at the poles), scaled so the energy is `irradiance`. With a
    `splat_height` below `height` the sun is splatted at that size and spread over the finer texels it covers
    (the angular size the data term that fitted it saw: a point sun on a 128-row map is a 1.4 deg speck)."""
    coarse = min(height, splat_height or height)
    weights = splat_weights(uv, coarse, irradiance.dtype)
    if coarse < height:
        weights = torch.nn.functional.interpolate(weights[None, None], size=(height, 2 * height), mode="nearest")[0, 0]
    energy = (weights * solid_angles(height, irradiance.dtype)).sum()
    return (weights / energy)[..., None] * irradiance


def splat_weights(uv: torch.Tensor, height: int, dtype: torch.dtype) -> torch.Tensor:
    """(H, 2H) bilinear weights of map coordinates `uv` on the four nearest texel centres (wrapping in azimuth,
    clamped at the poles)."""
    width = 2 * height
    x = torch.remainder(uv[0], 1.0) * width - 0.5
    y = (uv[1] * height - 0.5).clamp(0.0, height - 1.0)
    x0, y0 = torch.floor(x), torch.floor(y)
    fx, fy = x - x0, y - y0
    cols = [int(x0) % width, (int(x0) + 1) % width]
    rows = [int(y0), min(int(y0) + 1, height - 1)]
    weights = torch.zeros(height, width, dtype=dtype)
    return weights.index_put((torch.tensor([rows[0], rows[0], rows[1], rows[1]]),
                              torch.tensor([cols[0], cols[1], cols[0], cols[1]])),
                             torch.stack([(1 - fy) * (1 - fx), (1 - fy) * fx, fy * (1 - fx), fy * fx]).to(dtype),
                             accumulate=True)


def sun_direction_of(uv: torch.Tensor) -> np.ndarray:
    """World direction of map coordinates (u, v) (Mitsuba's convention, as dpi.envmap)."""
    u, v = (float(a) for a in uv)
    return directions_from_angles(np.array(v * math.pi), np.array(u * 2 * math.pi))


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
