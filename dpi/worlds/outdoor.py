"""Procedural outdoor environment maps: a mixture of landscapes, urban street canyons and overcast days.

Every scene is lit by one `Daylight` (`dpi.worlds.daylight`: Mitsuba's sunsky, broken clouds or an
overcast deck) and keeps a true HDR sun wherever nothing hides it. A landscape is the sky over a
tinted, textured Lambertian ground with a silhouette (hills, mountains, city blocks or a tree
line) on the horizon; an urban scene is a ray-cast street canyon (`dpi.worlds.street`). Overcast
scenes use either geometry. Everything is in dpi's (H, 2H, 3) +Y-up convention.
"""

from __future__ import annotations

import numpy as np

from dpi.io.images import with_luminance
from dpi.light.envmap import direction_to_texel, texel_angles, texel_directions
from dpi.worlds.daylight import Daylight, add_sun, irradiance, random_daylight, spherical_noise, upper_hemisphere
from dpi.worlds.street import SNOW, SNOW_PROBABILITY, random_street, street_envmap

SCENE_KINDS = {"urban": 0.4, "landscape": 0.4, "overcast": 0.2}
GROUND_TINTS = {  # linear RGB; only the chromaticity counts
    "grass": [0.35, 0.45, 0.20], "dry grass": [0.50, 0.47, 0.30], "dirt": [0.55, 0.45, 0.33],
    "concrete": [0.45, 0.45, 0.43], "sand": [0.62, 0.55, 0.42],
}
SKYLINE_KINDS = ("none", "hills", "mountains", "city", "trees")
SKYLINE_SLOPE_DEG = {"none": 90.0, "hills": 25.0, "mountains": 40.0, "city": 90.0, "trees": 80.0}


def random_ground_albedo(rng: np.random.Generator) -> np.ndarray:
    """RGB albedo of open ground: a grass/dirt/concrete/sand tint at luminance 0.05-0.5, or occasionally snow."""
    if rng.uniform() < SNOW_PROBABILITY:
        return with_luminance(SNOW, rng.uniform(0.5, 0.8))
    tints = list(GROUND_TINTS.values())
    return with_luminance(tints[rng.integers(len(tints))], rng.uniform(0.05, 0.5))


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
        return np.maximum(0, 4 * deg + 3 * deg * periodic_profile(phi, rng, 6, 1.5))
    if kind == "mountains":
        return np.maximum(0, 10 * deg + rng.uniform(3, 8) * deg * periodic_profile(phi, rng, 24, 1.0))
    if kind == "trees":
        return np.maximum(0, 7 * deg + 2 * deg * periodic_profile(phi, rng, 60, 0.6))
    edges = np.sort(rng.uniform(0, 2 * np.pi, size=rng.integers(8, 30)))
    heights = rng.uniform(2, 25, size=edges.size) * deg * (rng.uniform(size=edges.size) > 0.2)
    return heights[np.searchsorted(edges, phi) % edges.size]


def skyline_albedo(kind: str, ground: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """RGB albedo of a silhouette: vegetated or bare like the ground for hills, rock, dark foliage or facades."""
    if kind == "mountains":
        return with_luminance([0.50, 0.47, 0.44], rng.uniform(0.1, 0.35))
    if kind == "trees":
        return with_luminance([0.25, 0.35, 0.15], rng.uniform(0.05, 0.15))
    if kind == "city":
        return with_luminance([0.48, 0.46, 0.44], rng.uniform(0.15, 0.4))
    return ground * rng.uniform(0.6, 1.0)


def silhouette_coverage(top: np.ndarray, height: int) -> np.ndarray:
    """(H, W) fraction of each texel's elevation span below the silhouette top (W,): anti-aliased rows."""
    theta, _ = texel_angles(height)
    half = np.pi / (2 * height)
    low, high = np.pi / 2 - theta - half, np.pi / 2 - theta + half
    cover = np.clip((top[None, :] - np.maximum(low, 0)[:, None]) / (high - low)[:, None], 0, 1)
    return cover * upper_hemisphere(height)


def facing_normals(phi: np.ndarray, slope_deg: float) -> np.ndarray:
    """Unit normals (W, 3) of slopes rising away from the viewer at azimuths phi, tilted `slope_deg` from flat."""
    slope = np.radians(slope_deg)
    away = np.stack([np.sin(phi), np.zeros_like(phi), -np.cos(phi)], axis=-1)
    return -away * np.sin(slope) + np.array([0.0, 1.0, 0.0]) * np.cos(slope)


def lit_radiance(light: Daylight, albedo: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Lambertian radiance (K, 3) of surfaces with albedo (K, 3) or (3,) and unit normals (K, 3), unshadowed."""
    sun = np.maximum(normals @ light.sun, 0)[:, None] * light.sun_irradiance
    return albedo * (irradiance(light.sky, normals) + sun) / np.pi


def landscape_envmap(light: Daylight, rng: np.random.Generator) -> np.ndarray:
    """(H, 2H, 3) map of open country: the sky, a textured ground and a hazy silhouette on the horizon."""
    height = light.sky.shape[0]
    dirs = texel_directions(height)
    _, phi = texel_angles(height)
    upper = upper_hemisphere(height)[..., None]
    ground = random_ground_albedo(rng)
    furrows = dirs * [1.0, 3.0, 1.0]  # features foreshortened towards the horizon
    texture = np.clip(1 + 0.25 * spherical_noise(furrows, rng, base_freq=rng.uniform(3, 8)), 0.3, 2.0)[..., None]
    ground_radiance = lit_radiance(light, ground, np.array([[0.0, 1.0, 0.0]]))[0]
    env = np.where(upper, light.sky, ground_radiance * texture)

    kind = SKYLINE_KINDS[rng.integers(len(SKYLINE_KINDS))]
    top = skyline_elevation(phi, rng, kind)
    surface = lit_radiance(light, skyline_albedo(kind, ground, rng), facing_normals(phi, SKYLINE_SLOPE_DEG[kind]))
    haze = rng.uniform(0.1, 0.6)
    horizon_sky = light.sky[height // 2 - 1].mean(0)
    silhouette = (1 - haze) * surface[None] * texture + haze * horizon_sky
    cover = silhouette_coverage(top, height)[..., None]
    env = env * (1 - cover) + silhouette * cover
    _, sun_col = direction_to_texel(light.sun, height)
    return add_sun(env, light, visible=bool(np.arcsin(light.sun[1]) > top[sun_col]))


def scene_envmap(height: int, rng: np.random.Generator, kind: str) -> np.ndarray:
    """One (H, 2H, 3) float64 map of a scene kind; overcast days take the urban or landscape geometry at random."""
    if kind not in SCENE_KINDS:
        raise ValueError(f"unknown outdoor scene kind {kind!r}; use one of {sorted(SCENE_KINDS)}")
    light = random_daylight(height, rng, overcast_sky=kind == "overcast")
    geometry = kind if kind != "overcast" else ("urban", "landscape")[rng.integers(2)]
    if geometry == "urban":
        return street_envmap(light, random_street(rng))
    return landscape_envmap(light, rng)


def outdoor_envmap(height: int, rng: np.random.Generator, kind: str | None = None) -> np.ndarray:
    """One random (H, 2H, 3) float32 outdoor map; `kind` ('urban', 'landscape', 'overcast') forces a scene kind."""
    if kind is None:
        kind = str(rng.choice(list(SCENE_KINDS), p=list(SCENE_KINDS.values())))
    return scene_envmap(height, rng, kind).astype(np.float32)


def outdoor_envmaps(height: int, rng: np.random.Generator, count: int) -> np.ndarray:
    """`count` random outdoor maps (count, H, 2H, 3)."""
    return np.stack([outdoor_envmap(height, rng) for _ in range(count)])
