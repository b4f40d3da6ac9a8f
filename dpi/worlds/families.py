"""The worlds of each prior family ('outdoor', 'indoor') as one batch generator, and the check every generated
map passes (finite, non-negative, not black, a plausible dynamic range)."""

from __future__ import annotations

import itertools
import time
from typing import Callable

import numpy as np
from tqdm import tqdm

from dpi.io.images import luminance

MAX_DYNAMIC_RANGE = 1e8  # max / median luminance above this is implausible for our generators


class EnvmapCheckError(ValueError):
    """A generated map has NaN/Inf, negative values or an implausible dynamic range."""


def generator(family: str) -> Callable[[int, np.random.Generator, int], np.ndarray]:
    """The batch generator `(height, rng, count) -> (count, H, 2H, 3)` of a family ('outdoor' or 'indoor')."""
    if family == "outdoor":
        from dpi.worlds.outdoor import outdoor_envmaps

        return outdoor_envmaps
    if family == "indoor":
        from dpi.worlds.indoor import indoor_envmaps

        return indoor_envmaps
    raise ValueError(f"unknown env-map family {family!r}; use 'outdoor' or 'indoor'")


def check_envmap(env: np.ndarray, height: int) -> float:
    """Raise EnvmapCheckError unless `env` is a finite, non-negative (H, 2H, 3) map; returns its dynamic range."""
    if env.shape != (height, 2 * height, 3):
        raise EnvmapCheckError(f"map has shape {env.shape}, expected {(height, 2 * height, 3)}")
    if not np.isfinite(env).all():
        raise EnvmapCheckError("map contains NaN or Inf")
    if (env < 0).any():
        raise EnvmapCheckError("map contains negative radiance")
    lum = luminance(env)
    median = float(np.median(lum))
    if median <= 0:
        raise EnvmapCheckError("map is black over more than half of the sphere")
    dynamic_range = float(lum.max()) / median
    if dynamic_range > MAX_DYNAMIC_RANGE:
        raise EnvmapCheckError(f"dynamic range {dynamic_range:.3g} exceeds {MAX_DYNAMIC_RANGE:.0e}")
    return dynamic_range


def checked_envmaps(family: str, count: int, height: int, seed: int = 0,
                    progress: bool = True) -> tuple[list[np.ndarray], dict]:
    """`count` generated maps that pass `check_envmap` (map i from draws [seed, draw], failures replaced)
    and the manifest of the run: counts, rejections with reasons, time and dynamic range."""
    make = generator(family)
    maps, ranges, rejected = [], [], []
    start = time.perf_counter()
    with tqdm(total=count, desc=f"{family} maps", disable=not progress) as bar:
        for draw in itertools.count():
            if len(maps) == count:
                break
            env = make(height, np.random.default_rng([seed, draw]), 1)[0]
            try:
                ranges.append(check_envmap(env, height))
            except EnvmapCheckError as exc:
                rejected.append(f"draw {draw}: {exc}")
                continue
            maps.append(env)
            bar.update(1)
    seconds = time.perf_counter() - start
    manifest = {
        "family": family, "count": count, "height": height, "seed": seed,
        "rejected": rejected, "seconds": round(seconds, 2), "seconds_per_map": round(seconds / max(count, 1), 4),
        "dynamic_range_median": float(np.median(ranges)) if ranges else None,
        "dynamic_range_max": float(np.max(ranges)) if ranges else None,
    }
    return maps, manifest
