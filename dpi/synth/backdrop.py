"""Backgrounds of synthetic photo captures: what a camera sees behind the object.

A real walk-around capture shows the object in front of a room or a garden: nearby, textured
surfaces with parallax, which structure-from-motion needs and which a mask must cut away. The
`textured` backdrop is such a surround, a ground plane below the object and a cylindrical wall
around the whole capture, both covered with a multi-scale random texture. It is seen by the
cameras only: the object is still lit by the environment map alone, so the ground truth of
the inverse problem stays exact. `plain` is a uniform grey surround (a photo studio), `env` the
environment map itself (what Mitsuba renders behind the object).

`composite_backdrop` swaps the environment seen in a rendered image for the backdrop, per
sub-pixel ray, so the object's anti-aliased edge keeps its exact coverage.
"""

from __future__ import annotations

import numpy as np

from dpi.light.envmap import direction_to_texel, texel_directions, texel_solid_angles

BACKGROUNDS = ("env", "textured", "plain")
TILE = 64
"""side of the random colour table the texture is built from (it repeats every TILE cells)"""


def _table(seed: int) -> np.ndarray:
    """Random colours (TILE * TILE, 3) that the texture draws its cells from: a random hue at one of
    a few strongly different brightness levels, so neighbouring cells differ in luminance."""
    rng = np.random.default_rng(seed)
    hue = rng.uniform(0.2, 1.0, size=(TILE * TILE, 3))
    level = rng.choice([0.08, 0.3, 0.65, 1.0], size=(TILE * TILE, 1))
    return hue / hue.max(-1, keepdims=True) * level


def _cell(i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Pseudo-random table index of integer cell (i, j) (a hash, so the pattern does not repeat nearby)."""
    h = (i * 73856093) ^ (j * 19349663)
    return (h ^ (h >> 13)) % (TILE * TILE)


def backdrop_texture(u: np.ndarray, v: np.ndarray, seed: int = 0) -> np.ndarray:
    """Reflectance (..., 3) in [0.03, 0.9] at surface coordinates (u, v) (in cells of the coarse scale).

    Random colour cells at two scales, with strong luminance steps: corners and blobs that SIFT
    finds and matches across views.
    """
    table = _table(seed)
    out = np.zeros(np.shape(u) + (3,))
    for scale, weight in ((1.0, 0.7), (1 / 3, 0.3)):
        i = np.floor(np.asarray(u) / scale).astype(np.int64)
        j = np.floor(np.asarray(v) / scale).astype(np.int64)
        out += weight * table[_cell(i, j)]
    return 0.03 + 0.87 * out


def backdrop_hits(origins: np.ndarray, dirs: np.ndarray, ground: float, wall_radius: float,
                  behind: tuple[np.ndarray, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Texture coordinates (N, 2) where rays (N, 3) meet the ground plane y = ground or the wall
    x^2 + z^2 = wall_radius^2 (the nearer), and whether they hit either (rays going up over the
    wall see nothing: those are left to the caller). With `behind` (a horizontal unit direction n towards the
    cameras, a distance D) the wall is instead the plane n . x = -D behind the object."""
    o, d = np.asarray(origins, np.float64), np.asarray(dirs, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ground = np.where(d[:, 1] < -1e-9, (ground - o[:, 1]) / d[:, 1], np.inf)
        if behind is None:
            a = d[:, 0] ** 2 + d[:, 2] ** 2
            b = 2 * (o[:, 0] * d[:, 0] + o[:, 2] * d[:, 2])
            c = o[:, 0] ** 2 + o[:, 2] ** 2 - wall_radius**2
            t_wall = np.where(a > 1e-12, (-b + np.sqrt(np.maximum(b * b - 4 * a * c, 0))) / (2 * a), np.inf)
        else:
            normal, distance = np.asarray(behind[0], np.float64), behind[1]
            rate = d @ normal
            t_wall = np.where(rate < -1e-9, (-distance - o @ normal) / rate, np.inf)
    on_ground = t_ground <= t_wall
    t = np.where(on_ground, t_ground, t_wall)
    p = o + t[:, None] * d
    # cells of 0.4 units on the ground, on the far wall growing with its distance (similar sizes in the image)
    if behind is None:
        wall_uv = np.stack([np.arctan2(p[:, 0], p[:, 2]) * wall_radius, p[:, 1]], -1) / (0.12 * wall_radius)
    else:
        across = np.cross(np.asarray(behind[0], np.float64), [0.0, 1.0, 0.0])
        wall_uv = np.stack([p @ across, p[:, 1]], -1) / 0.4
    uv = np.where(on_ground[:, None], p[:, [0, 2]] / 0.4, wall_uv)
    return uv, np.isfinite(t)


def backdrop_level(env: np.ndarray) -> float:
    """Radiance of a white diffuse surface lit by the upper half of `env` (sets the backdrop's exposure)."""
    height = env.shape[0]
    weights = texel_solid_angles(height)[..., None] * (texel_directions(height)[..., 1:2] > 0)
    return float((env.mean(-1, keepdims=True) * weights).sum() / weights.sum())


def backdrop_radiance(origins: np.ndarray, dirs: np.ndarray, kind: str, env: np.ndarray, ground: float,
                      wall_radius: float, seed: int = 0, behind: tuple[np.ndarray, float] | None = None) -> np.ndarray:
    """Linear radiance (N, 3) a camera sees along rays that miss the object, for a background kind."""
    if kind not in BACKGROUNDS:
        raise ValueError(f"background must be one of {', '.join(BACKGROUNDS)}, got {kind!r}")
    row, col = direction_to_texel(dirs, env.shape[0])
    sky = env[row, col].astype(np.float64)
    if kind == "env":
        return sky
    level = backdrop_level(env)
    if kind == "plain":
        return np.full_like(sky, 0.45 * level)
    uv, hit = backdrop_hits(origins, dirs, ground, wall_radius, behind)
    return np.where(hit[:, None], level * backdrop_texture(uv[:, 0], uv[:, 1], seed), sky)


def composite_backdrop(image: np.ndarray, origins: np.ndarray, dirs: np.ndarray, hits: np.ndarray, kind: str,
                       env: np.ndarray, ground: float, wall_radius: float, seed: int = 0,
                       behind: tuple[np.ndarray, float] | None = None) -> np.ndarray:
    """A rendered image (h, w, 3) whose background (the env map) is replaced by a backdrop.

    origins, dirs: (h, w, s, 3) sub-pixel rays of the view; hits: (h, w, s) whether each hits the
    object. Pixels no ray hits become the backdrop's mean; partly covered pixels exchange their
    missing rays' environment radiance for the backdrop's.
    """
    if kind == "env":
        return image
    h, w, s = hits.shape
    o, d, miss = origins.reshape(-1, 3), dirs.reshape(-1, 3), ~hits.reshape(-1)
    row, col = direction_to_texel(d[miss], env.shape[0])
    delta = np.zeros((h * w * s, 3))
    back = backdrop_radiance(o[miss], d[miss], kind, env, ground, wall_radius, seed, behind)
    delta[miss] = back - env[row, col]
    background = np.zeros((h * w * s, 3))
    background[miss] = back
    covered = hits.any(-1)[..., None]
    out = np.where(covered, image + delta.reshape(h, w, s, 3).mean(2), background.reshape(h, w, s, 3).mean(2))
    return np.clip(out, 0.0, None).astype(np.float32)


def add_detail(albedo: np.ndarray, strength: float, seed: int = 0, cells: int = 32) -> np.ndarray:
    """Albedo (R, R, 3) multiplied by a pattern of random cells (`cells` across the texture), as
    printed texture on a real object: 1 - strength + strength * pattern, pattern in [0.1, 1]."""
    size = albedo.shape[0]
    v, u = np.meshgrid(np.arange(size), np.arange(size), indexing="ij")
    scale = size / cells
    pattern = backdrop_texture(u / scale, v / scale, seed).mean(-1, keepdims=True)
    pattern = 0.1 + 0.9 * (pattern - pattern.min()) / max(float(pattern.max() - pattern.min()), 1e-9)
    return np.clip(albedo * (1 - strength + strength * pattern), 0.0, 1.0).astype(np.float32)
