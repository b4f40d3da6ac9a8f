"""Bundler v0.3 cameras (dpi.capture.bundler): a written file reads back as the cameras it holds, and a camera
turned upright projects a point where the upright photo shows it."""

from __future__ import annotations

import numpy as np
import pytest

from dpi.capture.bundler import BundlerError, bundler_cameras, read_bundler, upright_camera
from dpi.capture.cameras import Camera, look_at
from dpi.io.images import upright


def bundler_text(cameras: list[Camera], keypoint: tuple[float, float], point=(0.0, 0.0, 0.0),
                 lens: tuple[float, float] = (0.0, 0.0)) -> str:
    """A Bundler file of cameras (principal point at the centre, radial terms `lens`) and one point seen by the
    first at `keypoint`."""
    lines = ["# Bundle file v0.3", f"{len(cameras)} 1"]
    for cam in cameras:
        rotation = cam.c2w[:3, :3].T
        lines += [f"{cam.fx} {lens[0]} {lens[1]}", *(" ".join(map(str, row)) for row in rotation),
                  " ".join(map(str, -rotation @ cam.center))]
    lines += [" ".join(map(str, point)), "255 255 255", f"1 0 0 {keypoint[0]} {keypoint[1]}"]
    return "\n".join(lines) + "\n"


def camera(position, width=60, height=40) -> Camera:
    return Camera(look_at(np.array(position, float), np.zeros(3)), width, height, 50.0, 50.0, width / 2, height / 2)


def test_a_written_bundler_file_reads_back_as_its_cameras(tmp_path):
    cams = [camera([3.0, 1.0, 2.0]), camera([-2.0, 0.5, 3.0])]
    path = tmp_path / "bundle.out"
    path.write_text(bundler_text(cams, (20.0, -10.0)))
    read = bundler_cameras(path, ["a", "b"], (60, 40))
    for cam, name in zip(cams, "ab"):
        np.testing.assert_allclose(read[name].c2w, cam.c2w, atol=1e-9)
        assert (read[name].width, read[name].height, read[name].fx) == (60, 40, 50.0)
    with pytest.raises(BundlerError, match="2 cameras for 3 images"):
        bundler_cameras(path, ["a", "b", "c"], (60, 40))


@pytest.mark.parametrize("orientation", [3, 6, 8])
def test_an_upright_camera_sees_a_point_where_the_upright_photo_has_it(orientation):
    cam = camera([3.0, 1.0, 2.0])
    point = np.array([[0.3, -0.2, 0.1]])
    x, y = cam.project(point)[0][0]
    photo = np.zeros((cam.height, cam.width, 1))
    photo[int(y), int(x)] = 1.0
    turned = upright(photo, orientation)
    (ux, uy) = upright_camera(cam, orientation).project(point)[0][0]
    assert turned.shape[:2] == (upright_camera(cam, orientation).height, upright_camera(cam, orientation).width)
    assert turned[int(uy), int(ux), 0] == 1.0


def test_the_solutions_own_reprojection_error_is_measured_under_its_lens(tmp_path):
    cam, point, (k1, k2) = camera([3.0, 1.0, 2.0]), np.array([0.3, -0.2, 0.1]), (-0.2, 0.1)
    local = cam.c2w[:3, :3].T @ (point - cam.center)
    p = -local[:2] / local[2]
    r2 = p @ p
    exact = cam.fx * (1 + k1 * r2 + k2 * r2 * r2) * p
    for shift, error in (((0.0, 0.0), 0.0), ((3.0, -4.0), 5.0)):
        path = tmp_path / f"bundle_{error:g}.out"
        path.write_text(bundler_text([cam], tuple(exact + shift), tuple(point), (k1, k2)))
        np.testing.assert_allclose(read_bundler(path).reprojection_errors(), [error], atol=1e-9)
