"""Env-map dataset: tone curve round trip, normalisation, area resize, augmentation, 8-bit clipping, folder loading."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from PIL import Image

from dpi.io.exr import write_exr
from dpi.light.tonecurve import family_encoding
from dpi.prior.data import (MEDIAN_TARGETS, EnvmapDataset, augment, clip_highlights, list_panoramas, median_target,
                            radiance_scale, read_dataset, read_panorama, resize_map, roll_columns, split_files,
                            to_prior_space)

ENCODINGS = [("outdoor", "paper"), ("indoor", "paper"), ("outdoor", "log")]


@pytest.mark.parametrize("family,encoding", ENCODINGS)
def test_encoding_round_trip(family: str, encoding: str) -> None:
    curve = family_encoding(family, encoding).with_scale(0.37)
    radiance = (torch.rand(3, 8, 16) + 0.01) * 0.37  # inside the range of every encoding
    torch.testing.assert_close(curve.to_radiance(curve.to_prior(radiance)), radiance, rtol=1e-4, atol=1e-7)
    x = torch.rand(3, 8, 16) * 2 - 1
    torch.testing.assert_close(curve.to_prior(curve.to_radiance(x)), x, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("family,encoding", ENCODINGS)
def test_prior_space_is_invariant_to_exposure(family: str, encoding: str) -> None:
    radiance = torch.rand(3, 8, 16) ** 3 * 10
    enc = family_encoding(family, encoding)
    target = median_target(family, enc)
    torch.testing.assert_close(to_prior_space(7.5 * radiance, enc, target), to_prior_space(radiance, enc, target))


def test_log_encoding_holds_a_sun() -> None:
    """A texel 2000x the median (the demo's sun is 1719x) survives the round trip; the paper's curve clamps it."""
    sky = torch.ones(3, 8, 16)
    sky[:, 2, 5] = 2000.0
    for encoding, kept in (("log", True), ("paper", False)):
        enc = family_encoding("outdoor", encoding)
        target = median_target("outdoor", enc)
        back = enc.with_scale(radiance_scale(sky, target)).to_radiance(to_prior_space(sky, enc, target))
        assert bool(torch.isclose(back[0, 2, 5], torch.tensor(2000.0), rtol=1e-3)) == kept
    low, high = family_encoding("outdoor", "log").range
    assert low <= 1e-2 and high >= 1e4


@pytest.mark.parametrize("family,encoding", ENCODINGS)
def test_clip_highlights_clips_luminance_at_a_multiple_of_the_median(family: str, encoding: str) -> None:
    """Chosen maps lose everything above `level` x median luminance, with its hue; the rest are untouched."""
    from dpi.io.images import luminance

    enc = family_encoding(family, encoding)
    target = median_target(family, enc)
    sky = torch.ones(2, 3, 8, 16) * torch.tensor([1.0, 0.9, 0.8])[:, None, None]
    sky[:, :, 2, 5] = torch.tensor([8.0, 4.0, 2.0])  # a warm bright texel
    x = torch.stack([to_prior_space(m, enc, target) for m in sky])
    out = clip_highlights(x, enc, target, 1.0, (2.0, 2.0))
    kept = clip_highlights(x, enc, target, 0.0, (2.0, 2.0))
    assert torch.equal(kept, x)
    radiance = enc.with_scale(1.0).to_radiance(out)
    lum = luminance(radiance.permute(0, 2, 3, 1))
    before = enc.with_scale(1.0).to_radiance(x)
    median = luminance(before.permute(0, 2, 3, 1)).flatten(1).median(1).values
    assert torch.allclose(lum.flatten(1).max(1).values, 2.0 * median, rtol=2e-3)
    hue = lambda c: c / c.sum(0)  # noqa: E731
    assert torch.allclose(hue(radiance[0, :, 2, 5]), hue(before[0, :, 2, 5]), atol=1e-3)
    assert torch.allclose(out[:, :, 0, 0], x[:, :, 0, 0])  # texels under the level keep their value


def test_radiance_scale_maps_median_to_target() -> None:
    radiance = torch.full((3, 4, 8), 2.0)
    assert radiance_scale(radiance, MEDIAN_TARGETS["outdoor"]) == pytest.approx(2.0 / MEDIAN_TARGETS["outdoor"])


def test_resize_map_preserves_mean_and_shape() -> None:
    image = torch.rand(3, 64, 128)
    small = resize_map(image, 16)
    assert small.shape == (3, 16, 32)
    assert float(small.mean()) == pytest.approx(float(image.mean()), rel=1e-5)
    assert resize_map(torch.rand(3, 20, 50), 8).shape == (3, 8, 16)


def test_roll_columns_is_a_rotation() -> None:
    x = torch.randn(3, 3, 4, 8)
    shifts = torch.tensor([0, 3, 7])
    rolled = roll_columns(x, shifts)
    for i, s in enumerate(shifts.tolist()):
        assert torch.equal(rolled[i], torch.roll(x[i], s, dims=-1))


def test_augment_keeps_shape_and_content() -> None:
    x = torch.randn(6, 3, 4, 8)
    y = augment(x, torch.Generator().manual_seed(0))
    assert y.shape == x.shape
    for xi, yi in zip(x, y):
        candidates = [torch.roll(v, s, dims=-1) for v in (xi, xi.flip(-1)) for s in range(8)]
        assert any(torch.equal(yi, c) for c in candidates)


def test_dataset_over_mixed_folder(tmp_path) -> None:
    rng = np.random.default_rng(0)
    write_exr(tmp_path / "a.exr", rng.uniform(0, 50, (32, 64, 3)).astype(np.float32))
    Image.fromarray(rng.integers(0, 255, (20, 40, 3), dtype=np.uint8)).save(tmp_path / "b.png")
    (tmp_path / "notes.txt").write_text("ignored")
    assert [p.name for p in list_panoramas(tmp_path)] == ["a.exr", "b.png"]
    ds = EnvmapDataset.from_folder(tmp_path, 8, "outdoor", family_encoding("outdoor"))
    assert len(ds) == 2 and ds.images.shape == (2, 3, 8, 16)
    batch = ds.batch(5, torch.Generator().manual_seed(1))
    assert batch.shape == (5, 3, 8, 16) and batch.min() >= -1 and batch.max() <= 1


def test_packed_dataset_round_trips_within_a_quantum(tmp_path) -> None:
    enc = family_encoding("indoor", "log")
    x = torch.rand(4, 3, 8, 16) * 2 - 1
    EnvmapDataset(x, "indoor", enc).save(tmp_path / "maps.npz")
    packed = read_dataset(tmp_path / "maps.npz", 8, "indoor", enc)
    assert packed.encoding == enc and packed.family == "indoor"
    assert (packed.images - x).abs().max() <= 1.0 / 255 + 1e-6
    batch = packed.batch(16, torch.Generator().manual_seed(0))
    assert batch.min() >= -1 and batch.max() <= 1 and not torch.isin(batch, packed.images).all()  # dithered
    with pytest.raises(ValueError, match="expected"):
        read_dataset(tmp_path / "maps.npz", 8, "outdoor", enc)


def test_hdr_files_are_read(tmp_path) -> None:
    from dpi.render import backend

    mi = backend.mitsuba()
    image = np.random.default_rng(1).uniform(0.01, 20, (8, 16, 3)).astype(np.float32)
    mi.Bitmap(image).write(str(tmp_path / "sky.hdr"))
    read = read_panorama(tmp_path / "sky.hdr")
    # RGBE shares one exponent per pixel: error is relative to the pixel's largest channel
    assert (np.abs(read - image) <= 0.01 * image.max(-1, keepdims=True)).all()


def test_empty_folder_is_an_error(tmp_path) -> None:
    with pytest.raises(FileNotFoundError, match="no panoramas"):
        list_panoramas(tmp_path)


def test_split_files_is_deterministic_and_disjoint(tmp_path) -> None:
    files = [tmp_path / f"{i}.exr" for i in range(10)]
    train, held = split_files(files, 0.2, seed=3)
    assert len(held) == 2 and set(train).isdisjoint(held) and split_files(files, 0.2, seed=3) == (train, held)
