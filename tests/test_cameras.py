"""Camera conventions: look-at, transforms.json and Mitsuba conversions, projection."""

import numpy as np
import pytest

from dpi.capture.cameras import (Camera, centre_rays, from_fov, from_mitsuba_matrix, look_at, orbit, pixel_rays, read_transforms, to_mitsuba,
                         write_transforms)


def test_look_at_is_a_rotation_looking_at_the_target():
    c2w = look_at([1.0, 2.0, 3.0], [0.0, 0.0, 0.0])
    R = c2w[:3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    forward = -R[:, 2]
    np.testing.assert_allclose(forward, -np.array([1, 2, 3]) / np.sqrt(14), atol=1e-12)


def test_transforms_json_round_trip():
    cams = [from_fov(p, 32, 24, 40.0, f"r_{i}") for i, p in enumerate(orbit(3, 4.0, (20.0,)))]
    cams[1].cx += 1.5
    cams[2].extras["held_out"] = True
    back = read_transforms(write_transforms([(f"images/{c.name}.png", c) for c in cams]))
    for (path, cam), orig in zip(back, cams):
        np.testing.assert_allclose(cam.c2w, orig.c2w)
        assert (cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height) == (orig.fx, orig.fy, orig.cx, orig.cy, 32, 24)
    assert back[2][1].extras["held_out"] is True


def test_nerf_synthetic_intrinsics_from_camera_angle():
    data = {"camera_angle_x": 2 * np.arctan(0.5), "frames": [{"file_path": "./r_0", "transform_matrix": np.eye(4).tolist()}]}
    (_, cam), = read_transforms(data, default_size=(100, 80))
    assert cam.fx == pytest.approx(100.0) and cam.cx == 50.0 and cam.cy == 40.0


def test_mitsuba_sensor_round_trip(mi):
    cam = from_fov(look_at([2.0, 1.0, 3.0], [0.1, 0.0, -0.2]), 32, 32, 45.0)
    sensor = mi.load_dict({**to_mitsuba(cam), "film": {"type": "hdrfilm", "width": 32, "height": 32}})
    to_world = np.array(mi.traverse(sensor)["to_world"].matrix, dtype=np.float64).reshape(4, 4)
    np.testing.assert_allclose(from_mitsuba_matrix(to_world), cam.c2w, atol=1e-5)


def test_pixel_rays_hit_the_projection_of_their_points():
    cam = Camera(look_at([0, 0, 5.0], [0, 0, 0]), 40, 30, 50.0, 50.0, 22.0, 14.0)
    origins, dirs = pixel_rays(cam, 1)
    points = origins[:, :, 0] + 5.0 * dirs[:, :, 0]
    px, depth = cam.project(points.reshape(-1, 3))
    ys, xs = np.mgrid[0:30, 0:40] + 0.5
    np.testing.assert_allclose(px, np.stack([xs.ravel(), ys.ravel()], -1), atol=1e-9)
    assert (depth > 0).all()


def test_centre_rays_are_the_pixel_rays_at_one_sample_in_a_ray_casters_rows():
    cam = Camera(look_at([1.0, 2.0, 5.0], [0, 0, 0]), 40, 30, 50.0, 55.0, 22.0, 14.0)
    origins, dirs = pixel_rays(cam, 1)
    rays = centre_rays(cam)
    assert rays.shape == (30 * 40, 6) and rays.dtype == np.float32
    np.testing.assert_allclose(rays[:, :3], origins.reshape(-1, 3), atol=1e-6)
    np.testing.assert_allclose(rays[:, 3:], dirs.reshape(-1, 3), atol=1e-6)
