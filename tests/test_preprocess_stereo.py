"""Multi-view stereo inside the hull: plane-sweep depth of a known plane, the robust free-space
distance, that carving never adds volume, highlight and grazing-depth detection, the fallback window."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dpi.capture.cameras import from_fov, look_at, orbit
from dpi.preprocess.stereo import (StereoParams, camera_rays, carve_with_depths, free_space, highlights,
                                   hull_depth_range, sweep_depth)

SIZE = 64


def plane_texture(seed: int = 0):
    """A smooth random texture t(x, y) on the world plane z = 0 (bilinear on a blurred noise grid)."""
    import cv2
    from scipy.ndimage import map_coordinates

    grid = cv2.GaussianBlur(np.random.default_rng(seed).random((96, 96)).astype(np.float32), (0, 0), 1.0)
    grid = (grid - grid.min()) / (grid.max() - grid.min())

    def texture(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return map_coordinates(grid, [(y + 3) * 16, (x + 3) * 16], order=1, mode="nearest").astype(np.float32)

    return texture


def plane_view(camera, texture) -> tuple[np.ndarray, np.ndarray]:
    """Image of the textured plane z = 0 and its camera-space depth in a view."""
    rays = camera_rays(camera)
    world = rays @ camera.c2w[:3, :3].T
    depth = -camera.center[2] / world[..., 2]  # rays are scaled to camera depth 1
    hit = camera.center + depth[..., None] * world
    return texture(hit[..., 0], hit[..., 1]), depth.astype(np.float32)


def test_plane_sweep_finds_a_textured_plane():
    texture = plane_texture()
    cameras = [from_fov(look_at((x, y, 5.0), (0.0, 0.0, 0.0)), SIZE, SIZE, 30.0, f"v{i}")
               for i, (x, y) in enumerate([(0.0, 0.0), (1.2, 0.0), (-1.2, 0.0), (0.0, 1.2), (0.0, -1.2)])]
    images = [plane_view(c, texture)[0] for c in cameras]
    truth = plane_view(cameras[0], texture)[1]
    cfg = StereoParams(planes=48, window=7, min_score=0.5, blur_px=0.0)
    depth, score = sweep_depth(images[0], cameras[0], list(zip(images[1:], cameras[1:])), truth - 0.6, truth + 0.6,
                               cfg)
    inner = np.s_[8:-8, 8:-8]
    found = depth[inner] > 0
    assert found.mean() > 0.9
    error = np.abs(depth[inner][found] - truth[inner][found]) / truth[inner][found]
    assert np.median(error) < 0.002 and np.percentile(error, 90) < 0.01
    assert np.median(score[inner]) > 0.9


def sphere_scene():
    """An open3d ray-casting scene of a unit sphere and 8 views around it."""
    import open3d as o3d

    mesh = o3d.geometry.TriangleMesh.create_sphere(1.0, 64)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    cameras = [from_fov(c2w, SIZE, SIZE, 40.0, f"v{i}") for i, c2w in enumerate(orbit(8, 4.0, (10.0,)))]
    return scene, cameras


def test_hull_depth_range_enters_and_leaves_a_sphere():
    scene, cameras = sphere_scene()
    near, far = hull_depth_range(scene, cameras[0], 10.0)
    centre = SIZE // 2
    assert near[centre, centre] == pytest.approx(3.0, abs=0.01) and far[centre, centre] == pytest.approx(5.0, abs=0.01)
    assert np.isinf(near[0, 0]) and np.isinf(far[0, 0])


def test_free_space_is_a_robust_signed_distance_to_the_seen_surface():
    scene, cameras = sphere_scene()
    depths = [np.where(np.isfinite(near), near, 0.0).astype(np.float32)
              for near in (hull_depth_range(scene, c, 10.0)[0] for c in cameras)]
    band = 0.2
    towards = cameras[0].center / np.linalg.norm(cameras[0].center)
    points = np.array([1.1 * towards, 0.95 * towards, np.zeros(3)])
    clean = free_space(points, depths, cameras, band, votes=2)
    assert 0.08 < clean[0] <= band  # 0.1 in front of the surface, farther along oblique views' rays
    assert -band <= clean[1] < -0.04  # just behind it
    assert clean[2] == -np.inf  # far behind every view's surface: no view has evidence
    # a view whose depths are all 0.5 too deep (a mirrored highlight) is outvoted by the two others that
    # see the point (a mean would carve it: the wrong view's clipped +0.2 outweighs their -0.05 and -0.08)
    wrong = [d + 0.5 * (d > 0) if i == 1 else d for i, d in enumerate(depths)]
    assert free_space(points[1:2], wrong, cameras, band, votes=2)[0] < 0


def test_carving_with_depths_only_removes_volume():
    scene, cameras = sphere_scene()
    depths = [np.where(np.isfinite(near), near, 0.0).astype(np.float32)
              for near in (hull_depth_range(scene, c, 10.0)[0] for c in cameras)]
    size = 0.05
    axis = np.arange(-1.5, 1.5 + size / 2, size)
    origin = np.full(3, axis[0])
    points = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1)
    cube = np.abs(points).max(-1) - 1.2  # a hull that is a cube around the sphere
    carved = carve_with_depths(cube, origin, size, cameras, depths, StereoParams(votes=2))
    assert (carved >= cube).all()
    radius = np.linalg.norm(points, axis=-1)
    in_front = (radius > 1.08) & (radius < 1.2) & (np.abs(points[..., 1]) < 0.3)  # seen before the sphere
    assert (carved[in_front] >= 0).mean() > 0.9
    assert (carved[radius < 0.9] < 0).all()


def test_highlights_finds_a_bright_spot_not_texture():
    rng = np.random.default_rng(1)
    image = np.repeat(0.2 + 0.1 * rng.random((SIZE, SIZE, 1)), 3, -1).astype(np.float32)
    ys, xs = np.mgrid[:SIZE, :SIZE]
    image += (3.0 * np.exp(-((xs - 40) ** 2 + (ys - 20) ** 2) / 8.0))[..., None]
    found = highlights(image, np.ones((SIZE, SIZE), bool), 1.3)
    assert found[20, 40]
    assert found.mean() < 0.1


def test_grazing_depths_are_found_from_the_depth_maps_own_normals():
    from scipy.ndimage import minimum_filter

    from dpi.preprocess.stereo import grazing

    camera = from_fov(look_at((0.0, 0.0, 0.0), (0.0, 0.0, -1.0)), 64, 48, 60.0)
    rays = camera_rays(camera)
    for tilt in (30.0, 60.0, 80.0):
        # the plane -z - k x = 2 in camera space (normal (k, 0, 1)), tilted `tilt` deg about the y axis
        k = np.tan(np.radians(tilt))
        depth = (2.0 / (1.0 - k * rays[..., 0])).astype(np.float32)
        depth[depth <= 0] = 0.0
        normal = np.array([k, 0.0, 1.0]) / np.hypot(k, 1.0)
        angle = np.degrees(np.arccos(np.abs(rays @ normal) / np.linalg.norm(rays, axis=-1)))
        found = grazing(depth, camera, 70.0)
        inner = np.zeros_like(found)  # pixels with a depth 2 px either way: the normal is known
        inner[2:-2, 2:-2] = minimum_filter(depth > 0, size=5)[2:-2, 2:-2]
        clear = inner & (np.abs(angle - 70.0) > 0.5)
        assert (found[clear] == (angle[clear] > 70.0)).all()
        assert not found[~inner].any()


def test_fallback_window_fills_only_what_the_fine_window_missed():
    """Noisy views of a textured plane: a 5 px window finds few consistent depths, the 13 px fallback
    fills the rest with accurate ones and leaves the fine window's depths as they were."""
    import open3d as o3d

    from dpi.preprocess.stereo import depth_maps

    texture = plane_texture()
    cameras = [from_fov(look_at((x, y, 5.0), (0.0, 0.0, 0.0)), SIZE, SIZE, 30.0, f"v{i}")
               for i, (x, y) in enumerate([(0.0, 0.0), (1.2, 0.0), (-1.2, 0.0), (0.0, 1.2), (0.0, -1.2)])]
    rng = np.random.default_rng(1)
    images = [np.repeat(plane_view(c, texture)[0][..., None] + 0.1 * rng.standard_normal((SIZE, SIZE, 1)), 3, -1)
              .astype(np.float32) for c in cameras]
    masks = [np.ones((SIZE, SIZE), bool)] * len(cameras)
    box = o3d.geometry.TriangleMesh.create_box(8, 8, 1.2).translate((-4, -4, -0.6))  # the "hull" around the plane
    hull = np.asarray(box.vertices), np.asarray(box.triangles)
    cfg = StereoParams(planes=48, window=5, fallback_window=0, min_score=0.5, blur_px=0.0, highlight_ratio=0,
                       neighbours=4, max_baseline_deg=60)
    fine = depth_maps(cameras, images, masks, *hull, cfg)[0]
    both = depth_maps(cameras, images, masks, *hull, replace(cfg, fallback_window=13))[0]
    truth = plane_view(cameras[0], texture)[1]
    inner = np.s_[8:-8, 8:-8]
    assert (fine[inner] > 0).mean() < 0.5 and (both[inner] > 0).mean() > 0.8
    assert np.array_equal(both[fine > 0], fine[fine > 0])
    assert all(m.all() for m in masks)  # the filters did not write into the caller's masks
    added = (both > 0) & (fine == 0)
    assert np.median(np.abs(both[added] - truth[added]) / truth[added]) < 0.01


@pytest.mark.parametrize("window", [1, 5, 11])
def test_box_mean_matches_an_average_pool_that_ignores_the_padding(window):
    import torch
    import torch.nn.functional as F

    from dpi.preprocess.stereo import _box

    x = torch.rand(3, 2, 17, 23, generator=torch.Generator().manual_seed(window))
    half = window // 2
    pooled = F.avg_pool2d(x, window, stride=1, padding=half, count_include_pad=False)
    assert torch.allclose(_box(x, window), pooled, atol=1e-6)


@pytest.mark.parametrize("factor, passes", [(0.5, 1), (2.0, 2)])
def test_a_second_stereo_pass_runs_only_where_the_first_opened_a_concavity(monkeypatch, factor, passes):
    """stereo_carve stops after a pass that removed less than NEXT_PASS_FROM of the hull (a convex object)."""
    from dpi.preprocess import geometry

    n = 16
    grid = (np.stack(np.indices((n, n, n)), -1) - (n - 1) / 2) / (n / 2)
    field = np.linalg.norm(grid, axis=-1) - 0.8  # a sphere, negative inside

    share = factor * geometry.NEXT_PASS_FROM

    def carve(field, origin, size, cameras, depths, cfg):  # removes `share` of the current hull's voxels
        inside = np.flatnonzero(field < 0)
        out = field.copy()
        out.flat[inside[: int(np.ceil(share * len(inside)))]] = 1.0
        return out

    monkeypatch.setattr("dpi.preprocess.stereo.depth_maps", lambda cameras, images, masks, *mesh_and_cfg: [
        np.zeros((4, 4))])
    monkeypatch.setattr("dpi.preprocess.stereo.carve_with_depths", carve)
    carved, summary = geometry.stereo_carve(field, np.zeros(3), 2 / n, [], [np.ones((4, 4), bool)], [],
                                           geometry.GeometryConfig())
    assert summary["passes"] == passes
    assert summary["voxels_removed"] == int(((field < 0) & (carved >= 0)).sum()) > 0
