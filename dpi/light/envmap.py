"""Equirectangular environment-map conventions, exactly as Mitsuba's `envmap` emitter reads them.

A map is (H, 2H, 3) linear RGB, row 0 at the zenith (+Y), row H-1 at the nadir. Mitsuba maps a
world direction d to u = atan2(d.x, -d.z) / 2pi (mod 1), v = acos(d.y) / pi, so column c looks
towards phi = 2pi (c + 0.5) / W measured from -Z towards +X. Mitsuba keeps extra wrap columns in
its `envmap.data` parameter (one after the map in older versions; one on each side in 3.9);
`pad_for_mitsuba` builds whichever layout the scene parameter has.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch

from dpi.io.exr import EXRError, read_exr
from dpi.io.images import ImageError, luminance, read_hdr, resize


def texel_angles(height: int) -> tuple[np.ndarray, np.ndarray]:
    """Polar angle theta (from +Y) per row and azimuth phi per column at texel centres."""
    theta = (np.arange(height) + 0.5) / height * np.pi
    phi = (np.arange(2 * height) + 0.5) / (2 * height) * 2 * np.pi
    return theta, phi


def directions_from_angles(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Unit world directions (..., 3) for polar angle theta from +Y and Mitsuba azimuth phi."""
    theta, phi = np.broadcast_arrays(theta, phi)
    s = np.sin(theta)
    return np.stack([np.sin(phi) * s, np.cos(theta), -np.cos(phi) * s], axis=-1)


def texel_directions(height: int) -> np.ndarray:
    """World direction (H, 2H, 3) at the centre of every texel of an H x 2H map."""
    theta, phi = texel_angles(height)
    return directions_from_angles(theta[:, None], phi[None, :])


def direction_to_uv(d: np.ndarray) -> np.ndarray:
    """Mitsuba's (u, v) in [0, 1)^2 for unit directions (..., 3)."""
    d = np.asarray(d, dtype=np.float64)
    u = np.mod(np.arctan2(d[..., 0], -d[..., 2]) / (2 * np.pi), 1.0)
    v = np.arccos(np.clip(d[..., 1], -1.0, 1.0)) / np.pi
    return np.stack([u, v], axis=-1)


def direction_to_texel(d: np.ndarray, height: int) -> tuple[np.ndarray, np.ndarray]:
    """(row, column) integer texel indices that a direction falls into."""
    uv = direction_to_uv(d)
    col = np.minimum((uv[..., 0] * 2 * height).astype(int), 2 * height - 1)
    row = np.minimum((uv[..., 1] * height).astype(int), height - 1)
    return row, col


def texel_solid_angles(height: int) -> np.ndarray:
    """Solid angle (H, 1) of one texel in each row; sums to 4 pi over the map."""
    edges = np.arange(height + 1) / height * np.pi
    band = np.cos(edges[:-1]) - np.cos(edges[1:])
    return (band * 2 * np.pi / (2 * height))[:, None]


def top_energy_share(env: np.ndarray, fraction: float = 0.005) -> float:
    """Share of an (H, 2H, 3) map's energy (luminance x texel solid angle) in its `fraction` of texels
    that carry the most of it (a sun's texels carry about half of a clear sky's)."""
    energy = (luminance(env) * texel_solid_angles(env.shape[0])).ravel()
    top = max(1, int(round(fraction * energy.size)))
    return float(np.sort(energy)[::-1][:top].sum() / energy.sum())


def pad_for_mitsuba(env: torch.Tensor, data_width: int) -> torch.Tensor:
    """Add Mitsuba's wrap columns to an (H, W, C) map so it has `data_width` columns."""
    width = env.shape[1]
    if data_width == width:
        return env
    if data_width == width + 1:
        return torch.cat([env, env[:, :1]], dim=1)
    if data_width == width + 2:
        return torch.cat([env[:, -1:], env, env[:, :1]], dim=1)
    raise ValueError(f"unexpected envmap data width {data_width} for a map of width {width}")


def unpad_from_mitsuba(data: np.ndarray, width: int) -> np.ndarray:
    """Inverse of `pad_for_mitsuba`: the (H, W, C) map inside Mitsuba's padded data."""
    extra = data.shape[1] - width
    start = 1 if extra == 2 else 0
    return data[:, start : start + width]


def rotate_azimuth(env: np.ndarray, degrees: float) -> np.ndarray:
    """The (H, W, C) map of the environment turned by `degrees` about the up axis (+Y, right-handed:
    counter-clockwise seen from above). Azimuth phi becomes phi - degrees, so the columns roll by
    -degrees / 360 * W, interpolated linearly between whole texels."""
    shift = -degrees / 360.0 * env.shape[1]
    whole = math.floor(shift)
    frac = shift - whole
    rolled = np.roll(env, whole, axis=1)
    return rolled if frac == 0 else (1 - frac) * rolled + frac * np.roll(env, whole + 1, axis=1)


def pad_equirect(x: torch.Tensor, pad: int) -> torch.Tensor:
    """Pad a channels-first map (..., H, W) by `pad` texels following the sphere: circularly in
    azimuth, and across each pole into the rows on the opposite side (rolled by W/2, rows mirrored)."""
    if pad == 0:
        return x
    half = x.shape[-1] // 2
    top = torch.roll(x[..., :pad, :].flip(-2), half, dims=-1)
    bottom = torch.roll(x[..., -pad:, :].flip(-2), half, dims=-1)
    x = torch.cat([top, x, bottom], dim=-2)
    return torch.cat([x[..., -pad:], x, x[..., :pad]], dim=-1)


class EnvmapLayoutError(ValueError):
    """An image that is not an equirectangular environment map in any layout dpi reads."""


def equirect(env: np.ndarray, source: str = "envmap") -> tuple[np.ndarray, list[str]]:
    """The (H, 2H, C) map of an equirect in the layouts authors ship, and a line per change made:
    a wrap column (the last column repeating the first, e.g. 128 x 257 or 256 x 257) is dropped, and
    a map between 1:1 and 2:1 (e.g. 256 x 256) is resampled to H x 2H. Anything else is an error."""
    notes = []
    height, width = shape = env.shape[:2]
    if width % 2 == 1 and width > 1:
        first, last = env[:, 0], env[:, -1]
        if np.abs(first - last).max() <= 1e-3 * max(float(np.abs(env).mean()), 1e-12):
            env = env[:, :-1]
            width -= 1
            notes.append(f"{source}: dropped the wrap column (the last column repeats the first): "
                         f"{height}x{width + 1} -> {height}x{width}")
    if width != 2 * height:
        if not height <= width < 2 * height:
            raise EnvmapLayoutError(f"{source}: {shape[0]}x{shape[1]} is not an equirectangular map: need H x 2H "
                                    "(or H x 2H+1 with a wrap column, or between H x H and H x 2H to resample)")
        env = resize(torch.from_numpy(np.ascontiguousarray(env, dtype=np.float32)), height, 2 * height).numpy()
        notes.append(f"{source}: resampled a {height}x{width} equirect to {height}x{2 * height}")
    return env, notes


def read_envmap(path: str | Path, log: bool = True) -> np.ndarray:
    """An environment map (H, 2H, 3) from an EXR (or a Radiance .hdr) in any layout `equirect` reads (its changes
    printed as log lines); an unreadable file, NaN/Inf/negative radiance, or radiance so large that a sum over the
    map overflows 32-bit floats is an error naming the file."""
    if Path(path).suffix.lower() == ".hdr":
        try:
            env = read_hdr(path)
        except ImageError as exc:
            raise EXRError(str(exc)) from None
    else:
        env = read_exr(path)
    if env.shape[-1] == 1:
        env = np.repeat(env, 3, axis=-1)
    if not np.isfinite(env).all() or (env < 0).any():
        raise EXRError(f"{path}: environment map has NaN, Inf or negative values")
    peak = float(env.max(initial=0.0))
    if peak * env.size >= float(np.finfo(np.float32).max):
        raise EXRError(f"{path}: environment map values up to {peak:.3g}: sums over its {env.size} values overflow "
                       "32-bit floats (a radiance scale gone wrong?)")
    env, notes = equirect(env[..., :3], str(path))
    for note in notes if log else []:
        print(note, flush=True)
    return env
