"""Procedural env-map datasets for the prior: generate, check and write N maps of one family (EXR or packed)."""

from __future__ import annotations

import itertools
import json
import time
from pathlib import Path
from typing import Callable

import numpy as np
import torch
from tqdm import tqdm

from dpi.io.atomic import write_json
from dpi.io.exr import write_exr
from dpi.io.images import luminance
from dpi.light.tonecurve import Encoding
from dpi.prior.data import EnvmapDataset, median_target, to_prior_space

MAX_DYNAMIC_RANGE = 1e8  # max / median luminance above this is implausible for our generators


class EnvmapCheckError(ValueError):
    """A generated map has NaN/Inf, negative values or an implausible dynamic range."""


def generator(family: str) -> Callable[[int, np.random.Generator, int], np.ndarray]:
    """The batch generator `(height, rng, count) -> (count, H, 2H, 3)` of a family ('outdoor' or 'indoor')."""
    if family == "outdoor":
        from dpi.prior.outdoor import outdoor_envmaps

        return outdoor_envmaps
    if family == "indoor":
        from dpi.prior.indoor import indoor_envmaps

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


def make_envmap_dataset(family: str, count: int, height: int, out_dir: str | Path, seed: int = 0,
                        progress: bool = True) -> dict:
    """Write `count` checked maps `{out_dir}/{family}_{i:05d}.exr` and `manifest.json`; returns the manifest.

    Each map is stored divided by its median luminance (half floats keep their relative precision
    there; the prior normalises every map by its median anyway). A map failing `check_envmap` is
    not written; it is listed under 'rejected' and replaced.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    maps, manifest = checked_envmaps(family, count, height, seed, progress)
    for i, env in enumerate(maps):
        normalised = env / float(np.median(luminance(env)))
        write_exr(out / f"{family}_{i:05d}.exr", np.minimum(normalised, 65000.0), half=True)
    write_json(out / "manifest.json", manifest)
    return manifest


def make_packed_dataset(family: str, count: int, height: int, out: str | Path, encoding: Encoding, seed: int = 0,
                        progress: bool = True) -> dict:
    """Generate `count` checked maps straight into a packed .npz in `encoding` (no EXR round trip) and
    write the manifest next to it (`{out}.json`); returns the manifest."""
    maps, manifest = checked_envmaps(family, count, height, seed, progress)
    target = median_target(family, encoding)
    images = torch.stack([to_prior_space(torch.from_numpy(env).permute(2, 0, 1), encoding, target) for env in maps])
    EnvmapDataset(images, family, encoding).save(out)
    write_json(Path(f"{out}.json"), {**manifest, "encoding": encoding.to_dict()})
    return manifest


def read_manifest(out_dir: str | Path) -> dict:
    """The manifest a `make_envmap_dataset` run left in `out_dir`."""
    return json.loads((Path(out_dir) / "manifest.json").read_text())
