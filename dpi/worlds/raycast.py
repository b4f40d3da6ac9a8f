"""The one raycaster of the procedural worlds (rooms and streets): primary rays of an equirect map, several per
texel on a grid of equal solid angle, the mean of their values per texel, and the slab test of rays against
axis-aligned boxes."""

from __future__ import annotations

import numpy as np

from dpi.light.envmap import directions_from_angles


def subtexel_directions(height: int, n: int) -> np.ndarray:
    """(H, 2H, n*n, 3) ray directions on an n x n grid of equal solid angle inside each texel."""
    offsets = (np.arange(n) + 0.5) / n
    cos_edges = np.cos(np.arange(height + 1) / height * np.pi)
    cos_t = cos_edges[:-1, None] + offsets[None] * (cos_edges[1:] - cos_edges[:-1])[:, None]  # (H, n)
    phi = (np.arange(2 * height)[:, None] + offsets[None]) / (2 * height) * 2 * np.pi  # (2H, n)
    theta = np.arccos(np.clip(cos_t, -1, 1))
    dirs = directions_from_angles(theta[:, None, :, None], phi[None, :, None, :])  # (H, 2H, n, n, 3)
    return dirs.reshape(height, 2 * height, n * n, 3)


def texel_mean(values: np.ndarray, height: int, n: int) -> np.ndarray:
    """(H, 2H, ...) means over each texel's rays of values (H * 2H * n*n, ...) in `subtexel_directions`' order."""
    return values.reshape(height, 2 * height, n * n, *values.shape[1:]).mean(2)


def slabs(origins: np.ndarray, dirs: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, ...]:
    """(entry t, exit t, entry axis, exit axis) of rays origins + t dirs (..., 3) through boxes [lo, hi] (..., 3),
    all broadcast together; a ray meets its box where entry <= exit."""
    shape = np.broadcast_shapes(origins.shape, dirs.shape, np.shape(lo), np.shape(hi))[:-1]
    t_near, t_far = np.full(shape, -np.inf), np.full(shape, np.inf)
    near_axis, far_axis = np.zeros(shape, int), np.zeros(shape, int)
    with np.errstate(divide="ignore", invalid="ignore"):
        for k in range(3):
            inv = 1.0 / dirs[..., k]
            t_lo, t_hi = (lo[..., k] - origins[..., k]) * inv, (hi[..., k] - origins[..., k]) * inv
            entry, exit_ = np.fmin(t_lo, t_hi), np.fmax(t_lo, t_hi)
            near_axis = np.where(entry > t_near, k, near_axis)
            far_axis = np.where(exit_ < t_far, k, far_axis)
            t_near, t_far = np.fmax(t_near, entry), np.fmin(t_far, exit_)
    return t_near, t_far, near_axis, far_axis
