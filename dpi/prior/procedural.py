"""Procedural env-map datasets for the prior: N checked maps of one family (dpi.worlds.families) written as EXR
or packed."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from dpi.io.atomic import write_json
from dpi.io.exr import write_exr
from dpi.io.images import luminance
from dpi.light.tonecurve import Encoding
from dpi.prior.data import EnvmapDataset, median_target, to_prior_space
from dpi.worlds.families import checked_envmaps


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
