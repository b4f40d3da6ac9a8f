"""Foreground masks: colour keying on a plain background, GrabCut from a sparse-point hull on a
textured one, the consensus prior without points, and the clean-up (largest part, small holes)."""

from __future__ import annotations

import numpy as np
import pytest

from dpi.cameras import from_fov, orbit, pixel_rays
from dpi.images import srgb_to_linear
from dpi.preprocess.accuracy import mask_iou
from dpi.preprocess.masks import MaskConfig, clean_mask, derive_masks, object_mask
from dpi.synth.backdrop import backdrop_texture

SIZE = 64


def sphere_view(camera, background: str, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Linear image and true mask of a textured unit sphere at the origin seen by `camera`."""
    origins, dirs = pixel_rays(camera)
    o, d = origins[:, :, 0], dirs[:, :, 0]
    b = (o * d).sum(-1)
    disc = b * b - ((o * o).sum(-1) - 1.0)
    mask = disc > 0
    t = -b - np.sqrt(np.maximum(disc, 0))
    p = o + t[..., None] * d
    shade = 0.35 + 0.65 * np.clip(p @ np.array([0.3, 0.8, 0.5]), 0, 1)
    checker = (np.sin(6 * p[..., 0]) * np.sin(6 * p[..., 1] + 1) > 0)[..., None]
    albedo = np.where(checker, [0.95, 0.45, 0.2], [0.85, 0.75, 0.3])
    if background == "plain":
        back = np.full((camera.height, camera.width, 3), 0.5)
    else:
        yy, xx = np.mgrid[: camera.height, : camera.width]
        back = backdrop_texture(xx / 5.0 + 7 * seed, yy / 5.0, seed=seed) * 0.8
    image = np.where(mask[..., None], albedo * shade[..., None], back)
    return srgb_to_linear(np.clip(image, 0, 1)), mask


@pytest.fixture(scope="module")
def cameras():
    return [from_fov(c2w, SIZE, SIZE, 40.0, f"v{i}") for i, c2w in enumerate(orbit(12, 4.0, (10.0, 35.0)))]


def surface_points(count: int = 200, seed: int = 0) -> np.ndarray:
    p = np.random.default_rng(seed).normal(size=(count, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def test_uniform_background_is_keyed(cameras):
    image, truth = sphere_view(cameras[0], "plain")
    mask, method = object_mask(image, cameras[0], MaskConfig(), surface_points())
    assert method == "key"
    assert mask_iou(mask, truth) > 0.97


def test_textured_background_uses_grabcut_from_the_points_hull(cameras):
    ious = []
    for i, cam in enumerate(cameras[:4]):
        image, truth = sphere_view(cam, "textured", seed=i)
        mask, method = object_mask(image, cam, MaskConfig(), surface_points(60, seed=i))
        assert method == "grabcut"
        ious.append(mask_iou(mask, truth))
    assert np.mean(ious) > 0.95, ious


def test_stray_points_do_not_become_foreground(cameras):
    image, truth = sphere_view(cameras[1], "textured", seed=1)
    points = np.concatenate([surface_points(60), [[2.5, 2.0, 0.0]]])  # one far-off point widens the hull
    mask, _ = object_mask(image, cameras[1], MaskConfig(), points)
    assert mask_iou(mask, truth) > 0.9


def test_consensus_prior_without_points(cameras, tmp_path):
    from dpi.images import read_mask, write_png

    images, truths = {}, {}
    for i, cam in enumerate(cameras):
        image, truths[cam.name] = sphere_view(cam, "textured", seed=i)
        images[cam.name] = tmp_path / f"{cam.name}.png"
        write_png(images[cam.name], image)
    summary = derive_masks(images, {c.name: c for c in cameras}, tmp_path / "masks", MaskConfig(method="grabcut"))
    assert summary["prior"] == "sphere, then consensus hull"
    ious = [mask_iou(read_mask(tmp_path / "masks" / f"{n}.png"), truths[n]) for n in truths]
    assert np.mean(ious) > 0.9, ious


def test_clean_mask_keeps_the_largest_part_and_big_holes():
    mask = np.zeros((40, 40), bool)
    mask[5:35, 5:35] = True
    mask[10:12, 10:12] = False  # small hole: filled
    mask[18:28, 18:28] = False  # large hole (a torus' opening): kept
    mask[0:2, 38:40] = True  # speck: dropped
    out = clean_mask(mask, fill_holes_below=0.05)
    assert out[10:12, 10:12].all() and not out[18:28, 18:28].any() and not out[0:2, 38:40].any()
