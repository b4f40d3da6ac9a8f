"""Structure from motion: COLMAP's pose convention, the normalised frame, and clear failures."""

from __future__ import annotations

import numpy as np
import pytest

from dpi.capture.cameras import from_fov, orbit
from dpi.preprocess.accuracy import pose_errors, umeyama
from dpi.preprocess.sfm import SfMConfig, SfMError, SparseModel, colmap_to_camera, normalise, run_sfm, transform_camera


def random_rotation(rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def test_colmap_world_to_camera_projects_like_dpi_camera():
    import pycolmap

    rng = np.random.default_rng(0)
    rigid = pycolmap.Rigid3d(pycolmap.Rotation3d(random_rotation(rng)), rng.normal(size=3))
    colmap_camera = pycolmap.Camera.create_from_model_name(1, "SIMPLE_PINHOLE", 80.0, 64, 48)
    in_camera = np.column_stack([rng.uniform(-1, 1, (50, 2)), rng.uniform(2, 5, 50)])
    world = in_camera @ rigid.rotation.matrix() - rigid.rotation.matrix().T @ rigid.translation  # inverse(rigid)
    expected = colmap_camera.img_from_cam(rigid * world)
    camera = colmap_to_camera(rigid.matrix(), 64, 48, 80.0, 80.0, 32.0, 24.0, "v")
    xy, depth = camera.project(world)
    np.testing.assert_allclose(xy, expected, atol=1e-6)
    np.testing.assert_allclose(depth, in_camera[:, 2], atol=1e-9)


def test_normalise_recovers_the_object_frame():
    rng = np.random.default_rng(1)
    truth = {f"v{i}": from_fov(c2w, 64, 64, 40.0, f"v{i}") for i, c2w in enumerate(orbit(12, 4.0, (15.0, 30.0)))}
    sphere = rng.normal(size=(400, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    wall = rng.normal(size=(300, 3))
    wall = 12 * wall / np.linalg.norm(wall, axis=1, keepdims=True)  # surroundings, far from the object
    # the same scene in an arbitrary COLMAP frame: x -> s R x + t
    scale, rotation, shift = 0.37, random_rotation(rng), rng.normal(size=3) * 5
    moved = {n: transform_camera(c, scale, rotation, -rotation.T @ shift / scale) for n, c in truth.items()}
    points = np.concatenate([sphere, wall]) @ (scale * rotation).T + shift
    from dpi.preprocess.sfm import object_points

    on_object = object_points(points, list(moved.values()), 0.75)
    assert on_object[:400].mean() > 0.95 and not on_object[400:].any()
    model = normalise(SparseModel(moved, points, np.zeros_like(points), on_object))
    errors = pose_errors(model.cameras, truth)
    assert errors["rotation_error_deg_max"] < 1e-6 and errors["centre_error_max"] < 0.05
    up = np.mean([c.c2w[:3, 1] for c in model.cameras.values()], axis=0)
    assert up[1] > 0.9  # +Y up, from the ring of cameras
    object_radius = np.percentile(np.linalg.norm(model.points[model.on_object], axis=1), 98)
    assert object_radius == pytest.approx(1.0, abs=0.02)
    s, r, _ = umeyama(np.array([model.cameras[n].center for n in truth]), np.array([truth[n].center for n in truth]))
    assert s == pytest.approx(1.0, abs=0.03)


def test_featureless_images_fail_with_a_clear_error(tmp_path):
    from dpi.io.images import write_srgb

    for i in range(3):
        write_srgb(tmp_path / "images" / f"{i}.png", np.full((32, 32, 3), 0.2 + 0.1 * i, np.float32))
    with pytest.raises(SfMError, match="no model") as info:
        run_sfm(sorted((tmp_path / "images").glob("*.png")), tmp_path / "colmap", SfMConfig())
    assert info.value.summary["images"] == 3


@pytest.fixture(scope="module")
def photos(tmp_path_factory):
    """32 photos of 240 px in front of the textured backdrop, all around (file order = the walk's order)."""
    from dpi.synth.capture import SynthConfig, make_synthetic_capture

    root = tmp_path_factory.mktemp("walk")
    make_synthetic_capture(root, SynthConfig(views=32, held_out_every=0, width=240, height=240, spp=4, env_height=16,
                                             texture_size=128, camera_distance=6.0, elevations_deg=(15.0, 30.0),
                                             albedo_detail=0.6, background="textured", image_format="png",
                                             photos_only=True), threads=2, progress=False)
    return sorted((root / "images").glob("*.png"))


def test_photos_out_of_order_are_matched_in_full_when_their_order_registers_too_few(photos, tmp_path, monkeypatch):
    """matcher auto on a larger capture: neighbours in file order first; shuffled names break the walk's order, so
    every pair is matched and every photo registers."""
    import shutil

    monkeypatch.setattr("dpi.preprocess.sfm.EXHAUSTIVE_MAX_IMAGES", 4)
    monkeypatch.setattr("dpi.preprocess.sfm.SEQUENTIAL_OVERLAP", 4)
    in_order = run_sfm(photos, tmp_path / "ordered")
    assert in_order.summary["matcher"] == "sequential" and in_order.summary["registered"] == len(photos)

    shuffled = tmp_path / "shuffled"
    shuffled.mkdir()
    order = np.random.default_rng(3).permutation(len(photos))
    for k, i in enumerate(order):
        shutil.copy(photos[i], shuffled / f"{k:03d}.png")
    model = run_sfm(sorted(shuffled.glob("*.png")), tmp_path / "colmap")
    assert model.summary["matcher"] == "sequential, then exhaustive"
    assert model.summary["registered"] == len(photos)
