"""Daylight over procedural outdoor scenes: a sky radiance map plus the sun as a direction and an irradiance.

The physical sky and sun come from Mitsuba's `sunsky` (`dpi.worlds.skies.sunsky_envmap`): the sun-to-sky
ratio is the model's, never clamped. The sun is kept apart from the sky so that scene geometry can
shade surfaces with it (n.s times its irradiance) and hide it; `add_sun` draws it back as a disc with
its aureole (dpi.light.sunlight), its power preserved. Broken clouds dim the sun; an overcast deck
hides it and spreads the sky's total irradiance times a transmittance over a CIE-overcast-like dome.
All maps are (H, 2H, 3) in dpi's +Y-up convention; a `Daylight` sky is zero below the horizon.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from dpi.io.images import luminance
from dpi.light.envmap import direction_to_texel, texel_angles, texel_directions, texel_solid_angles
from dpi.light.sunlight import draw_sun_np
from dpi.worlds.skies import SkyParams, sun_direction, sunsky_envmap

LOW_SUN_PROBABILITY = 0.3  # share of suns drawn between 0.5 and 10 degrees of elevation
CLOUD_WHITE = np.array([1.0, 0.98, 0.95])
OVERCAST_GREY = np.array([0.97, 1.0, 1.06])  # a slightly blue-grey deck, normalised below to unit luminance


@dataclass
class Daylight:
    """The light of one outdoor scene: sky radiance without the sun, and the sun's direction and irradiance."""

    sky: np.ndarray  # (H, 2H, 3) radiance of the sky (clouds included, sun excluded); zero below the horizon
    sun: np.ndarray  # (3,) unit world direction towards the sun
    sun_irradiance: np.ndarray  # (3,) RGB irradiance on a plane facing the sun; zero when clouds hide it


def spherical_noise(dirs: np.ndarray, rng: np.random.Generator, base_freq: float = 2.0,
                    octaves: int = 5, features: int = 24) -> np.ndarray:
    """Seamless fBm on the sphere (...,) with zero mean and unit std: random Fourier features of directions (..., 3)."""
    total = np.zeros(dirs.shape[:-1])
    for octave in range(octaves):
        w = rng.normal(size=(features, 3)) * base_freq * 2.0**octave
        b = rng.uniform(0, 2 * np.pi, size=features)
        total += 0.5**octave * np.cos(dirs @ w.T + b).sum(-1)
    return (total - total.mean()) / (total.std() + 1e-8)


def random_sun_elevation(rng: np.random.Generator) -> float:
    """Sun elevation in degrees: often low (0.5-10: long shadows, red light), else uniform in its sine up to 80."""
    if rng.uniform() < LOW_SUN_PROBABILITY:
        return float(rng.uniform(0.5, 10.0))
    return float(np.degrees(np.arcsin(rng.uniform(np.sin(np.radians(10.0)), np.sin(np.radians(80.0))))))


def random_sky_params(rng: np.random.Generator) -> SkyParams:
    """Sun position, turbidity and the sky model's ground albedo drawn over the range of natural daylight."""
    return SkyParams(sun_elevation_deg=random_sun_elevation(rng), sun_azimuth_deg=float(rng.uniform(0, 360)),
                     turbidity=float(rng.uniform(1.8, 8.0)), ground_albedo=float(rng.uniform(0.08, 0.45)),
                     supersample=1)


def upper_hemisphere(height: int) -> np.ndarray:
    """(H, 1) mask of the rows above the horizon."""
    theta, _ = texel_angles(height)
    return (theta < np.pi / 2)[:, None]


def irradiance(radiance: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """RGB irradiance (K, 3) that an (H, 2H, 3) radiance map casts on planes with unit normals (K, 3)."""
    height = radiance.shape[0]
    cosines = np.maximum(texel_directions(height).reshape(-1, 3) @ normals.T, 0.0)  # (N, K)
    weighted = (radiance * texel_solid_angles(height)[:, :, None]).reshape(-1, 3)
    return cosines.T @ weighted


def physical_daylight(height: int, params: SkyParams) -> Daylight:
    """Clear-sky daylight of Mitsuba's sunsky: its sky above the horizon and its sun's deposited power as irradiance."""
    full = sunsky_envmap(height, params).astype(np.float64)
    sky = sunsky_envmap(height, replace(params, sun_scale=0.0)).astype(np.float64) * upper_hemisphere(height)[..., None]
    sun_part = (full - sky) * upper_hemisphere(height)[..., None]
    sun_irradiance = (np.maximum(sun_part, 0) * texel_solid_angles(height)[:, :, None]).sum((0, 1))
    return Daylight(sky=sky, sun=sun_direction(params.sun_elevation_deg, params.sun_azimuth_deg),
                    sun_irradiance=sun_irradiance)


def cloudy(light: Daylight, rng: np.random.Generator, cover: float) -> Daylight:
    """The daylight under broken clouds covering a fraction `cover` of the sky; a cloud over the sun dims it."""
    if cover <= 0:
        return light
    height = light.sky.shape[0]
    dirs = texel_directions(height)
    stretch = dirs * np.array([1.0, rng.uniform(1.5, 4.0), 1.0])
    noise = spherical_noise(stretch, rng, base_freq=rng.uniform(1.5, 4.0))
    alpha = np.clip((noise - np.quantile(noise, 1 - cover)) / 0.6, 0, 1) * upper_hemisphere(height)
    sun_row, sun_col = direction_to_texel(light.sun, height)
    sun_visibility = 1 - 0.9 * alpha[sun_row, sun_col]
    horizon_sky = light.sky[height // 2 - 1].mean(0)
    brightness = horizon_sky.mean() * rng.uniform(0.7, 1.8) * (1 + 0.5 * sun_visibility)
    shading = np.clip(1 + 0.25 * spherical_noise(stretch, rng, base_freq=6.0), 0.4, 1.6)
    cloud = brightness * shading[..., None] * CLOUD_WHITE
    sky = light.sky * (1 - alpha[..., None]) + cloud * alpha[..., None]
    return Daylight(sky=sky, sun=light.sun, sun_irradiance=light.sun_irradiance * sun_visibility)


def overcast(light: Daylight, rng: np.random.Generator, transmittance: float) -> Daylight:
    """A cloud deck hiding the sun: the sky's total horizontal irradiance times `transmittance`, spread over a
    CIE-overcast-like dome (zenith 3x the horizon), textured and a little brighter towards the hidden sun."""
    height = light.sky.shape[0]
    up = np.array([[0.0, 1.0, 0.0]])
    total = irradiance(light.sky, up)[0] + light.sun_irradiance * max(light.sun[1], 0.0)
    dirs = texel_directions(height)
    dome = (1 + 2 * np.maximum(dirs[..., 1], 0)) / 3
    layers = dirs * [1.0, 3.0, 1.0]  # flattened cloud features
    texture = np.exp(rng.uniform(0.05, 0.25) * spherical_noise(layers, rng, base_freq=rng.uniform(2, 5)))
    glow = 1 + rng.uniform(0.0, 1.5) * (transmittance - 0.2) / 0.4 * np.exp((dirs @ light.sun - 1) / 0.08)
    pattern = dome * texture * glow * upper_hemisphere(height)
    tint = OVERCAST_GREY / luminance(OVERCAST_GREY)
    unit = irradiance(pattern[..., None] * tint, up)[0]
    sky = pattern[..., None] * tint * transmittance * luminance(total) / luminance(unit)
    return Daylight(sky=sky, sun=light.sun, sun_irradiance=np.zeros(3))


def add_sun(env: np.ndarray, light: Daylight, visible: bool) -> np.ndarray:
    """The map with the sun drawn as a disc with its aureole (dpi.light.sunlight), its power kept, unless something
    hides it."""
    if not visible or not light.sun_irradiance.any():
        return env
    return env + draw_sun_np(light.sun, light.sun_irradiance, env.shape[0]).astype(env.dtype)


def random_daylight(height: int, rng: np.random.Generator, overcast_sky: bool) -> Daylight:
    """Daylight at a random sun and turbidity: under broken clouds (clear to nearly covered) or an overcast deck."""
    light = physical_daylight(height, random_sky_params(rng))
    if overcast_sky:
        return overcast(light, rng, transmittance=float(rng.uniform(0.2, 0.6)))
    cover = float(rng.choice([0.0, rng.uniform(0.1, 0.6), rng.uniform(0.6, 0.9)], p=[0.35, 0.45, 0.2]))
    return cloudy(light, rng, cover)
