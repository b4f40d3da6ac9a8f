"""Procedural outdoor environment maps from Mitsuba's physically based `sunsky` emitter.

Mitsuba's `sunsky` is defined with +Z up (its sky is zero for directions with z < 0) and takes
`sun_direction` in that frame. dpi scenes are +Y up, so every query direction d = (x, y, z) of
the envmap grid is rotated by `Y_UP_TO_Z_UP` before evaluation. The sun disc (0.5 degrees) is far
smaller than a texel, so it is deposited into the texel it falls in with its radiant power
preserved; the lower hemisphere gets a Lambertian ground lit by sun and sky.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dpi.light.envmap import direction_to_texel, directions_from_angles, texel_angles, texel_solid_angles
from dpi.render import backend

# Proper rotation taking +Y (dpi up) to +Z (sunsky up): (x, y, z) -> (x, -z, y).
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
SUN_APERTURE_DEG = 0.5358  # Mitsuba's default sun_aperture (angular diameter)


@dataclass
class SkyParams:
    """Parameters of one procedural sun-and-sky map."""

    sun_elevation_deg: float = 35.0
    sun_azimuth_deg: float = 60.0
    turbidity: float = 3.0
    ground_albedo: float = 0.3
    sun_scale: float = 1.0
    sky_scale: float = 1.0
    supersample: int = 2


def sun_direction(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """World (+Y up) unit direction to the sun; azimuth follows the envmap's phi convention."""
    theta = math.radians(90.0 - elevation_deg)
    return directions_from_angles(np.array(theta), np.array(math.radians(azimuth_deg)))


def _eval_emitter(emitter, directions: np.ndarray) -> np.ndarray:
    """Radiance (N, 3) an emitter sends towards the origin from world directions (N, 3)."""
    import drjit as dr
    import mitsuba as mi

    q = directions @ Y_UP_TO_Z_UP.T
    si = dr.zeros(mi.SurfaceInteraction3f, q.shape[0])
    si.wi = mi.Vector3f(-q[:, 0], -q[:, 1], -q[:, 2])
    return np.array(emitter.eval(si)).T.astype(np.float64)


def sunsky_envmap(height: int, params: SkyParams | None = None) -> np.ndarray:
    """(H, 2H, 3) float32 linear HDR map of a sunsky with ground, in dpi's envmap convention."""
    p = params or SkyParams()
    mi = backend.mitsuba()
    sun = sun_direction(p.sun_elevation_deg, p.sun_azimuth_deg)
    sun_q = mi.ScalarVector3f(*(Y_UP_TO_Z_UP @ sun))
    common = {"type": "sunsky", "sun_direction": sun_q, "turbidity": p.turbidity, "albedo": p.ground_albedo}
    sky = mi.load_dict({**common, "sun_scale": 0.0, "sky_scale": p.sky_scale})
    sun_only = mi.load_dict({**common, "sun_scale": p.sun_scale, "sky_scale": 0.0})

    # Sky: average of s x s sub-texel samples per texel.
    s = p.supersample
    theta_f = (np.arange(height * s) + 0.5) / (height * s) * np.pi
    phi_f = (np.arange(2 * height * s) + 0.5) / (2 * height * s) * 2 * np.pi
    dirs = directions_from_angles(theta_f[:, None], phi_f[None, :]).reshape(-1, 3)
    weights = np.sin(theta_f)[:, None, None]
    radiance = _eval_emitter(sky, dirs).reshape(height * s, 2 * height * s, 3)
    env = (radiance * weights).reshape(height, s, 2 * height, s, 3).sum((1, 3))
    env /= weights.reshape(height, s, 1, 1).sum(1)[:, :, None].reshape(height, 1, 1) * s

    # Sun: power-preserving deposit into its texel.
    omega_texel = texel_solid_angles(height)
    sun_radiance = np.zeros(3)
    if p.sun_elevation_deg > 0 and p.sun_scale > 0:
        sun_radiance = _eval_emitter(sun_only, sun[None])[0]
        omega_sun = 2 * np.pi * (1 - math.cos(math.radians(SUN_APERTURE_DEG / 2)))
        row, col = direction_to_texel(sun, height)
        env[row, col] += sun_radiance * omega_sun / omega_texel[row, 0]

    # Ground: Lambertian, lit by the upper hemisphere (sky + sun).
    theta, _ = texel_angles(height)
    upper = theta < np.pi / 2
    cos_t = np.cos(theta)[:, None, None]
    irradiance = (env * cos_t * omega_texel[:, :, None])[upper].sum((0, 1))
    env[~upper] = p.ground_albedo * irradiance / np.pi
    return env.astype(np.float32)
