"""The ground test: plane depths of a known camera, the ground's height fitted from the background,
mask pixels that see the ground found (and the object's kept), a plain ground left alone."""

from __future__ import annotations

import numpy as np
import pytest

from dpi.capture.cameras import from_fov, look_at, orbit
from dpi.preprocess.ground import fit_ground, ground_pixels, plane_depths, remove_ground
from dpi.preprocess.stereo import StereoParams, camera_rays, grey, neighbour_views

SIZE = 96
UP = np.array([0.0, 1.0, 0.0])
CARD = 0.8
"""height of the object: a textured horizontal card |x|, |z| <= 0.5 floating over the ground y = 0"""


def texture(seed: int):
    """A smooth random texture t(u, v) on a plane (bilinear on a blurred noise grid)."""
    import cv2
    from scipy.ndimage import map_coordinates

    grid = cv2.GaussianBlur(np.random.default_rng(seed).random((64, 64)).astype(np.float32), (0, 0), 0.7)
    grid = (grid - grid.min()) / (grid.max() - grid.min())
    return lambda u, v: map_coordinates(grid, [(v + 8) * 4, (u + 8) * 4], order=1, mode="nearest")


def scene_view(camera, ground, card) -> tuple[np.ndarray, np.ndarray]:
    """Linear RGB image (h, w, 3) of the card over the ground, and the card's silhouette."""
    rays = camera_rays(camera) @ camera.c2w[:3, :3].T
    with np.errstate(divide="ignore", invalid="ignore"):
        t_card = (CARD - camera.center[1]) / rays[..., 1]
        t_ground = -camera.center[1] / rays[..., 1]
    on_card = camera.center + t_card[..., None] * rays
    silhouette = (t_card > 0) & (np.abs(on_card[..., 0]) <= 0.5) & (np.abs(on_card[..., 2]) <= 0.5)
    on_ground = camera.center + t_ground[..., None] * rays
    value = np.where(silhouette, card(on_card[..., 0], on_card[..., 2]), ground(on_ground[..., 0], on_ground[..., 2]))
    return np.repeat((0.05 + 0.8 * value)[..., None], 3, -1).astype(np.float32), silhouette


def hull() -> tuple[np.ndarray, np.ndarray]:
    """A closed box around the card, as the carved hull of masks that took some ground would be."""
    import trimesh

    box = trimesh.creation.box(bounds=[[-0.8, 0.3, -0.8], [0.8, 0.9, 0.8]])
    return np.asarray(box.vertices), np.asarray(box.faces)


def render_capture(size: int):
    """24 views of size x size px from 45 deg above, masks that took a ring of ground around the card
    (10 px wide at 96 px)."""
    import cv2

    cameras = [from_fov(c2w, size, size, 40.0) for c2w in orbit(24, 4.0, (45.0,), target=(0.0, 0.4, 0.0))]
    ground, card = texture(0), texture(1)
    views = [scene_view(cam, ground, card) for cam in cameras]
    ring = np.ones((2 * (10 * size // SIZE) + 1,) * 2, np.uint8)
    masks = [cv2.dilate(s.astype(np.uint8), ring) > 0 for _, s in views]
    return cameras, [im for im, _ in views], [s for _, s in views], masks


@pytest.fixture(scope="module")
def capture():
    return render_capture(SIZE)


def wrongly_removed(ground: list[np.ndarray], silhouettes: list[np.ndarray]) -> np.ndarray:
    """Distances (px) from the silhouette's edge of the object pixels that `ground` took for ground."""
    import cv2

    depth = [cv2.distanceTransform(s.astype(np.uint8), cv2.DIST_L2, 3) for s in silhouettes]
    return np.concatenate([d[g & s] for d, g, s in zip(depth, ground, silhouettes)])


def test_plane_depths_of_a_camera_looking_down():
    camera = from_fov(look_at((0.0, 2.0, 0.0), (0.0, 0.0, 0.0), up=(0.0, 0.0, -1.0)), 33, 33, 60.0)
    depth = plane_depths(camera, UP, np.array([0.0, 1.5, 3.0]))
    assert depth[0, 16, 16] == pytest.approx(2.0) and depth[1, 16, 16] == pytest.approx(0.5)
    assert (depth[2] == -1).all()  # a plane above the camera: no ray meets it going down
    corner = camera_rays(camera)[0, 0] @ camera.c2w[:3, :3].T
    assert depth[0, 0, 0] == pytest.approx(-2.0 / corner[1], rel=1e-5)


def test_the_grounds_height_is_fitted_from_the_background(capture):
    cameras, images, _, masks = capture
    cfg = StereoParams()
    greys = [grey(im, cfg.blur_px) for im in images]
    neighbours = neighbour_views(cameras, np.array([0.0, 0.4, 0.0]), cfg.neighbours, cfg.max_baseline_deg)
    height, score = fit_ground(greys, cameras, masks, neighbours, UP, lowest=0.7, diagonal=1.5, cfg=cfg)
    pixel = 4.0 / cameras[0].fx  # a pixel's footprint at the object
    assert abs(height) <= pixel and score > 0.5  # most background pixels near the card match it


def test_mask_pixels_that_see_the_ground_are_found(capture):
    cameras, images, silhouettes, masks = capture
    cfg = StereoParams()
    greys = [grey(im, cfg.blur_px) for im in images]
    neighbours = neighbour_views(cameras, np.array([0.0, 0.4, 0.0]), cfg.neighbours, cfg.max_baseline_deg)
    ground = ground_pixels(greys, cameras, masks, neighbours, UP, 0.0, hull(), cfg)
    ring = sum(int((m & ~s).sum()) for m, s in zip(masks, silhouettes))
    found = sum(int((g & ~s).sum()) for g, s in zip(ground, silhouettes))
    assert found >= 0.8 * ring
    # of the card, only its edge goes: pixels whose NCC window (and the blur's 2 sigma) reaches over the
    # silhouette into the ground
    wrong = wrongly_removed(ground, silhouettes)
    assert wrong.max() <= cfg.window // 2 + 2 * cfg.blur_px + 0.5
    assert len(wrong) <= 0.15 * sum(int(s.sum()) for s in silhouettes)
    assert all(not (g & ~m).any() for g, m in zip(ground, masks))  # only mask pixels leave


def test_a_plain_ground_leaves_the_masks_alone(capture):
    cameras, images, silhouettes, masks = capture
    plain = [np.where(s[..., None], im, 0.4).astype(np.float32) for im, s in zip(images, silhouettes)]
    kept, summary = remove_ground(cameras, masks, plain, UP, hull(), StereoParams())
    assert summary["match"] < StereoParams().ground_fit and summary["removed_fraction"] == 0
    assert all((k == m).all() for k, m in zip(kept, masks))


def test_large_photos_are_matched_at_the_working_size_and_their_masks_lose_the_ground():
    from dpi.preprocess.geometry import without_ground, working_photos

    cameras, images, silhouettes, masks = render_capture(2 * SIZE)
    photos = working_photos(cameras, masks, images, SIZE)
    assert photos[0][0].width == SIZE and photos[1][0].shape == photos[2][0].shape[:2] == (SIZE, SIZE)
    kept, photos, summary = without_ground(masks, photos, UP, hull(), StereoParams())
    assert summary["removed_fraction"] > 0 and photos[1][0].shape == (SIZE, SIZE)
    ring = sum(int((m & ~s).sum()) for m, s in zip(masks, silhouettes))
    found = sum(int((m & ~k & ~s).sum()) for m, k, s in zip(masks, kept, silhouettes))
    assert found >= 0.8 * ring
    # the card loses only its edge: what the working size's NCC window and blur reach, twice as wide here
    cfg = StereoParams()
    wrong = wrongly_removed([m & ~k for m, k in zip(masks, kept)], silhouettes)
    assert wrong.max() <= 2 * (cfg.window // 2 + 2 * cfg.blur_px + 1)
    assert len(wrong) <= 0.15 * sum(int(s.sum()) for s in silhouettes)
    assert all(not (k & ~m).any() for k, m in zip(kept, masks))
