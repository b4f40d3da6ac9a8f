"""Points under given cameras (dpi.preprocess.known_poses): the pose conversion's round trip, and a textured sphere's
triangulated points on its surface."""

import numpy as np

from dpi.capture.cameras import Camera, Lens, from_fov, orbit, pixel_rays
from dpi.io.images import write_srgb
from dpi.preprocess.known_poses import camera_from_world, colmap_camera, triangulate_known
from dpi.preprocess.sfm import colmap_to_camera


def cell_sphere_view(camera: Camera) -> np.ndarray:
    """A unit sphere at the origin painted with random grey cells (features SIFT can match), on a plain grey."""
    origins, dirs = pixel_rays(camera)
    o, d = origins[:, :, 0], dirs[:, :, 0]
    b = (o * d).sum(-1)
    disc = b * b - ((o * o).sum(-1) - 1.0)
    p = o + (-b - np.sqrt(np.maximum(disc, 0)))[..., None] * d
    cell = np.floor(p * 6).astype(np.int64) @ np.array([73856093, 19349663, 83492791])
    albedo = ((cell[..., None] * np.array([1, 7, 13])) % 97) / 97.0
    return np.where((disc > 0)[..., None], 0.1 + 0.8 * albedo, 0.5)


def test_the_pose_given_to_colmap_comes_back_as_the_camera():
    camera = from_fov(orbit(5, 3.0, (20.0,))[2], 80, 60, 45.0, "v")
    back = colmap_to_camera(camera_from_world(camera), 80, 60, camera.fx, camera.fy, camera.cx, camera.cy, "v")
    np.testing.assert_allclose(back.c2w, camera.c2w, atol=1e-12)
    lensed = Camera(camera.c2w, 80, 60, camera.fx, camera.fy, camera.cx, camera.cy, "v", lens=Lens(k1=-0.1, k2=0.02))
    assert colmap_camera(lensed, 3).model_name == "OPENCV" and colmap_camera(camera, 3).model_name == "PINHOLE"
    np.testing.assert_allclose(colmap_camera(lensed, 3).params, [camera.fx, camera.fy, camera.cx, camera.cy,
                                                                 -0.1, 0.02, 0.0, 0.0])


def test_points_triangulated_under_given_cameras_lie_on_the_object(tmp_path):
    cameras = {f"v{i}": from_fov(c2w, 128, 128, 40.0, f"v{i}") for i, c2w in enumerate(orbit(24, 4.0, (10.0, 35.0)))}
    for name, camera in cameras.items():
        write_srgb(tmp_path / "images" / f"{name}.png", cell_sphere_view(camera))
    model = triangulate_known(sorted((tmp_path / "images").glob("*.png")), cameras, tmp_path / "colmap")
    assert model.cameras == cameras and model.summary["cameras"] == "given"
    assert len(model.points) >= 30 and model.on_object.all()  # every point is on the sphere every camera sees
    radius = np.linalg.norm(model.points, axis=1)
    assert abs(np.median(radius) - 1.0) < 0.02 and np.mean(np.abs(radius - 1.0) < 0.05) > 0.9
