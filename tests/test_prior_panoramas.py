"""Real panoramas in the prior's diet: the manifest's checks and splits, the packed set, mixing and recolouring."""

from __future__ import annotations

import csv

import numpy as np
import pytest
import torch

from dpi.io.exr import write_exr
from dpi.io.images import luminance
from dpi.light.tonecurve import family_encoding
from dpi.prior.data import EXPOSURE_JITTER, EnvmapDataset, recolour
from dpi.prior.panoramas import MANIFEST, Panorama, build_panorama_set, panorama_files, read_manifest, sha256_of


def panorama(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (0.5 + rng.random((16, 32, 3))).astype(np.float32)


@pytest.fixture
def folder_and_manifest(tmp_path):
    folder = tmp_path / "panoramas"
    folder.mkdir()
    for i, name in enumerate(("park.exr", "street.exr", "room.exr", "mine.exr")):
        write_exr(folder / name, panorama(i))
    rows = {name: Panorama(name, family, "sky" if family == "outdoor" else "indoor", split, "CC0-1.0", "github:o/r",
                           name, "0" * 40, "https://x", sha256_of(folder / name))
            for name, family, split in (("park.exr", "outdoor", "train"), ("street.exr", "outdoor", "held_out"),
                                        ("room.exr", "indoor", "train"))}
    return folder, rows


def test_the_shipped_manifest_names_sources_licences_and_checksums():
    entries = read_manifest()
    assert len(entries) >= 84
    for entry in entries.values():
        assert entry.licence.startswith(("CC0", "MIT", "BSD")) and len(entry.sha256) == 64 and entry.commit
        assert entry.source.startswith(("github:", "pip:", "debian:"))
        if entry.source.startswith("github:"):
            assert len(entry.commit) == 40
        assert "pmndrs" not in entry.source  # held back for evaluation


def test_the_held_out_split_covers_every_kind_of_light():
    held = [e for e in read_manifest().values() if e.split == "held_out"]
    assert len(held) >= 12
    assert {e.kind for e in held} == {"sun", "sky", "indoor", "studio"}
    assert all(sum(e.kind == kind for e in held) >= 3 for kind in ("sun", "sky", "indoor", "studio"))


def test_splits_follow_the_manifest_and_a_users_own_files_are_training_data(folder_and_manifest):
    folder, manifest = folder_and_manifest
    assert [p.name for p in panorama_files(folder, "outdoor", "train", manifest)] == ["mine.exr", "park.exr"]
    assert [p.name for p in panorama_files(folder, "outdoor", "held_out", manifest)] == ["street.exr"]
    assert [p.name for p in panorama_files(folder, "indoor", "train", manifest)] == ["mine.exr", "room.exr"]
    data = build_panorama_set(folder, "outdoor", 8, family_encoding("outdoor", "log"), "held_out", manifest)
    assert data.images.shape == (1, 3, 8, 16) and float(data.images.abs().max()) <= 1.0


def test_a_file_that_does_not_match_its_checksum_is_named(folder_and_manifest):
    folder, manifest = folder_and_manifest
    write_exr(folder / "park.exr", 2 * panorama(0))
    with pytest.raises(ValueError, match="park.exr: SHA-256 differs"):
        panorama_files(folder, "outdoor", "train", manifest)


def test_a_manifest_row_without_its_checksum_is_an_error(tmp_path):
    path = tmp_path / "m.csv"
    with open(MANIFEST) as src:
        rows = list(csv.DictReader(src))
    rows[0]["sha256"] = ""
    with open(path, "w", newline="") as out:
        writer = csv.DictWriter(out, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    with pytest.raises(ValueError, match="line 2: missing sha256"):
        read_manifest(path)


def test_a_mixed_dataset_draws_each_part_at_its_fraction():
    encoding = family_encoding("outdoor", "log")
    worlds = EnvmapDataset(torch.full((50, 3, 4, 8), -0.5), "outdoor", encoding)
    real = EnvmapDataset(torch.full((2, 3, 4, 8), 0.5), "outdoor", encoding)
    mixed = EnvmapDataset.mixed([worlds, real], [0.75, 0.25])
    idx = torch.multinomial(mixed.weights, 20000, replacement=True, generator=torch.Generator().manual_seed(0))
    assert float((idx >= 50).float().mean()) == pytest.approx(0.25, abs=0.01)
    with pytest.raises(ValueError, match="differ"):
        EnvmapDataset.mixed([worlds, EnvmapDataset(torch.zeros(1, 3, 8, 16), "outdoor", encoding)], [0.5, 0.5])


def test_recolouring_is_a_gain_per_image_and_channel_with_the_exposure_spread():
    encoding = family_encoding("outdoor", "log")
    x = 0.1 * torch.randn(400, 3, 4, 8, generator=torch.Generator().manual_seed(1))
    out = recolour(x, encoding, torch.Generator().manual_seed(2))
    unit = encoding.with_scale(1.0)
    gain = unit.to_radiance(out) / unit.to_radiance(x)
    torch.testing.assert_close(gain, gain[..., :1, :1].expand_as(gain), rtol=1e-4, atol=0)
    exposure = torch.log(luminance(gain[:, :, 0, 0]))
    assert float(exposure.std()) == pytest.approx(EXPOSURE_JITTER, rel=0.15)


def test_a_tilt_rotates_the_sphere_about_the_horizontal_axis():
    from dpi.light.envmap import texel_directions
    from dpi.prior.data import tilt

    d = torch.from_numpy(texel_directions(32)).float()
    # a map that is a smooth function of direction: its tilt must equal the function at R^T d
    field = lambda v: 0.5 * v[..., 1] + 0.3 * v[..., 2] + 0.2 * v[..., 0]  # noqa: E731
    x = field(d)[None, None].repeat(2, 3, 1, 1)
    out = tilt(x, torch.tensor([0.0, 10.0]))
    torch.testing.assert_close(out[0], x[0], atol=1e-5, rtol=0)
    a = np.deg2rad(10.0)
    source = torch.stack([d[..., 0], np.cos(a) * d[..., 1] + np.sin(a) * d[..., 2],
                          -np.sin(a) * d[..., 1] + np.cos(a) * d[..., 2]], dim=-1)
    assert float((out[1, 0] - field(source)).abs().max()) < 0.01
    assert float((out[1, 0] - x[1, 0]).abs().max()) > 0.05
