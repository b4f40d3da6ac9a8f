"""Procedural outdoor environment maps: Mitsuba sunsky plus clouds, a skyline and a textured ground.

The physically based sky comes from `dpi.skies.sunsky_envmap`; on top of it, clouds (thresholded
spherical noise) cover the sky and dim the sun, a silhouette (hills, mountains, city blocks or a
tree line) rises above the horizon, and the Lambertian ground gets a tinted noise albedo, so the
maps are not only smooth gradients. Everything is in dpi's (H, 2H, 3) +Y-up convention.
"""

from __future__ import annotations

import numpy as np

from dpi.envmap import texel_angles, texel_directions
from dpi.skies import SkyParams, sunsky_envmap

GROUND_TINTS = np.array([[0.35, 0.45, 0.20], [0.55, 0.48, 0.35], [0.40, 0.40, 0.40], [0.30, 0.35, 0.25]])
SKYLINE_KINDS = ("none", "hills", "mountains", "city", "trees")


def spherical_noise(dirs: np.ndarray, rng: np.random.Generator, base_freq: float = 2.0,
                    octaves: int = 5, features: int = 24) -> np.ndarray:
    """Seamless fBm on the sphere (...,) with zero mean and unit std, from random Fourier features of directions (..., 3)."""
    total = np.zeros(dirs.shape[:-1])
    for octave in range(octaves):
        w = rng.normal(size=(features, 3)) * base_freq * 2.0**octave
        b = rng.uniform(0, 2 * np.pi, size=features)
        total += 0.5**octave * np.cos(dirs @ w.T + b).sum(-1)
    return (total - total.mean()) / (total.std() + 1e-8)


def periodic_profile(phi: np.ndarray, rng: np.random.Generator, harmonics: int, roughness: float) -> np.ndarray:
    """Random periodic function of azimuth phi (W,) with zero mean and unit std (harmonic amplitudes ~ k^-roughness)."""
    k = np.arange(1, harmonics + 1)
    amp = k.astype(float) ** -roughness * rng.uniform(0.5, 1.0, size=harmonics)
    profile = (amp[:, None] * np.cos(k[:, None] * phi[None] + rng.uniform(0, 2 * np.pi, (harmonics, 1)))).sum(0)
    return (profile - profile.mean()) / (profile.std() + 1e-8)


def skyline_elevation(phi: np.ndarray, rng: np.random.Generator, kind: str) -> np.ndarray:
    """Elevation angle (W,) in radians of the silhouette top per column; <= 0 where there is none."""
    deg = np.pi / 180
    if kind == "none":
        return np.zeros_like(phi)
    if kind == "hills":
        return np.maximum(0, 3 * deg + 2.5 * deg * periodic_profile(phi, rng, 6, 1.5))
    if kind == "mountains":
        return np.maximum(0, 8 * deg + rng.uniform(3, 8) * deg * periodic_profile(phi, rng, 24, 1.0))
    if kind == "trees":
        return np.maximum(0, 6 * deg + 2 * deg * periodic_profile(phi, rng, 60, 0.6))
    edges = np.sort(rng.uniform(0, 2 * np.pi, size=rng.integers(8, 30)))
    heights = rng.uniform(2, 25, size=edges.size) * deg * (rng.uniform(size=edges.size) > 0.2)
    return heights[np.searchsorted(edges, phi) % edges.size]


def random_sky_params(rng: np.random.Generator) -> SkyParams:
    """Sun position, turbidity and ground albedo drawn over the range of natural daylight."""
    elevation = rng.uniform(0.5, 4.0) if rng.uniform() < 0.08 else 90 - np.degrees(np.arccos(rng.uniform(0.03, 0.97)))
    return SkyParams(sun_elevation_deg=float(elevation), sun_azimuth_deg=float(rng.uniform(0, 360)),
                     turbidity=float(rng.uniform(1.8, 8.0)), ground_albedo=float(rng.uniform(0.08, 0.45)),
                     supersample=1)


def outdoor_envmap(height: int, rng: np.random.Generator) -> np.ndarray:
    """One random (H, 2H, 3) float32 outdoor map: sunsky, clouds, skyline and textured ground."""
    params = random_sky_params(rng)
    full = sunsky_envmap(height, params).astype(np.float64)
    sky_only = sunsky_envmap(height, SkyParams(**{**params.__dict__, "sun_scale": 0.0})).astype(np.float64)
    sun_part = full - sky_only
    dirs = texel_directions(height)
    theta, phi = texel_angles(height)
    elevation = np.pi / 2 - theta[:, None] * np.ones((1, 2 * height))
    upper = elevation > 0

    # Clouds: coverage from thresholded, horizontally stretched noise; they also shade the sun.
    stretch = dirs * np.array([1.0, rng.uniform(1.5, 4.0), 1.0])
    cover = rng.choice([0.0, rng.uniform(0.1, 0.6), rng.uniform(0.6, 1.0)], p=[0.25, 0.5, 0.25])
    noise = spherical_noise(stretch, rng, base_freq=rng.uniform(1.5, 4.0))
    threshold = np.quantile(noise, 1 - cover) if cover > 0 else np.inf
    alpha = np.clip((noise - threshold) / 0.6, 0, 1) * upper if cover > 0 else np.zeros_like(noise)
    horizon_sky = sky_only[height // 2 - 1].mean(0)
    sun_row, sun_col = np.unravel_index(np.argmax(sun_part[:height // 2].sum(-1)), (height // 2, 2 * height))
    sun_visibility = 1 - 0.9 * alpha[sun_row, sun_col]
    cloud_brightness = horizon_sky.mean() * rng.uniform(0.7, 1.8) * (1 + 0.5 * sun_visibility * (params.sun_elevation_deg > 0))
    shading = np.clip(1 + 0.25 * spherical_noise(stretch, rng, base_freq=6.0), 0.4, 1.6)
    cloud = cloud_brightness * shading[..., None] * np.array([1.0, 0.98, 0.95])
    env = sky_only * (1 - alpha[..., None]) + cloud * alpha[..., None]
    env += sun_part * upper[..., None] * sun_visibility

    # Ground: irradiance / pi from Mitsuba's Lambertian ground, times a tinted noise albedo.
    ground_lit = (sky_only + sun_visibility * sun_part) / params.ground_albedo
    tint = GROUND_TINTS[rng.integers(len(GROUND_TINTS))] * rng.uniform(0.4, 1.2)
    texture = np.clip(1 + 0.35 * spherical_noise(dirs, rng, base_freq=rng.uniform(4, 12)), 0.2, 2.0)
    env = np.where(upper[..., None], env, ground_lit * tint * texture[..., None])

    # Skyline: silhouette lit like the ground, blended into the horizon haze with distance.
    top = skyline_elevation(phi, rng, SKYLINE_KINDS[rng.integers(len(SKYLINE_KINDS))])
    inside = upper & (elevation < top[None, :])
    haze = rng.uniform(0.1, 0.7)
    object_albedo = tint * rng.uniform(0.3, 0.9) * texture[..., None]
    ground_light = ground_lit[height - 1].mean(0)
    silhouette = (1 - haze) * object_albedo * ground_light + haze * horizon_sky
    env = np.where(inside[..., None], silhouette, env)
    return np.maximum(env, 0).astype(np.float32)


def outdoor_envmaps(height: int, rng: np.random.Generator, count: int) -> np.ndarray:
    """`count` random outdoor maps (count, H, 2H, 3)."""
    return np.stack([outdoor_envmap(height, rng) for _ in range(count)])
