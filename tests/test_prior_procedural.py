"""Procedural env-map generators (outdoor sunsky scenes, path-traced rooms), checks and the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dpi.cli import main
from dpi.io.exr import read_exr
from dpi.io.images import luminance
from dpi.prior.procedural import make_envmap_dataset
from dpi.worlds.families import EnvmapCheckError, check_envmap
from dpi.worlds.outdoor import outdoor_envmap, spherical_noise


def test_outdoor_map_is_valid_and_seeded() -> None:
    a = outdoor_envmap(16, np.random.default_rng(3))
    b = outdoor_envmap(16, np.random.default_rng(3))
    assert np.array_equal(a, b)
    assert check_envmap(a, 16) > 1.0
    assert luminance(a[:8]).max() > luminance(a[8:]).max()  # the brightest texel is in the sky


def test_spherical_noise_is_standardised() -> None:
    dirs = np.random.default_rng(0).normal(size=(500, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    n = spherical_noise(dirs, np.random.default_rng(1))
    assert n.shape == (500,) and abs(n.mean()) < 1e-9 and n.std() == pytest.approx(1.0)


def test_check_rejects_bad_maps() -> None:
    good = np.ones((4, 8, 3), np.float32)
    check_envmap(good, 4)
    for bad, message in [(good * np.nan, "NaN"), (-good, "negative"), (np.zeros_like(good), "black"),
                         (good[:, :6], "shape")]:
        with pytest.raises(EnvmapCheckError, match=message):
            check_envmap(bad, 4)


def test_make_envmaps_command(tmp_path) -> None:
    main(["make-envmaps", "--family", "outdoor", "--count", "3", "--height", "8", "--out", str(tmp_path)])
    files = sorted(tmp_path.glob("outdoor_*.exr"))
    assert len(files) == 3 and read_exr(files[0]).shape == (8, 16, 3)
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["count"] == 3 and manifest["rejected"] == []


def test_unknown_family_is_an_error(tmp_path) -> None:
    with pytest.raises(ValueError, match="family"):
        make_envmap_dataset("underwater", 1, 8, tmp_path)
