"""Cameras with lenses (issue: real photos): the distortion models nerfstudio, instant-ngp and COLMAP write are
read (top level or per frame), a model dpi cannot undistort is named in one line, and the capture stage
removes the distortion once with OpenCV, so the later stages see pinhole views."""

import json

import cv2
import numpy as np
import pytest
from capture_helpers import SIZE, cameras, edit_transforms, make_capture

from dpi.capture import CaptureError, camera_from_json, camera_to_json, load_capture, read_capture_json
from dpi.capture.cameras import Camera, Lens, from_fov, look_at
from dpi.capture.undistort import distort_image, intrinsics, undistort_image
from dpi.io.images import read_image, read_mask
from dpi.preprocess.derive import normalise_capture

BARREL = Lens(k1=-0.12, k2=0.03, p1=0.001, p2=-0.002)
FISHEYE = Lens(fisheye=True, k1=0.05, k2=-0.01, k3=0.002, k4=0.0)


@pytest.mark.parametrize("where", ["top", "frame"])
def test_distortion_is_read_top_level_or_per_frame(tmp_path, where):
    root = make_capture(tmp_path / "cap")
    edit_transforms(root, lambda d: (d if where == "top" else d["frames"][1]).update(k1=-0.12, k2="0.03", p1=0.001,
                                                                                       p2=-0.002))
    lenses = [v.camera.lens for v in load_capture(root).views]
    assert lenses[1] == BARREL
    assert all(lens == (BARREL if where == "top" else None) for i, lens in enumerate(lenses) if i != 1)


def test_fisheye_and_colmap_model_names_are_read(tmp_path):
    root = make_capture(tmp_path / "cap")
    edit_transforms(root, lambda d: d["frames"][0].update(camera_model="OPENCV_FISHEYE", k1=0.05, k2=-0.01, k3=0.002))
    edit_transforms(root, lambda d: d["frames"][2].update(camera_model="SIMPLE_RADIAL", k1=0.02))
    views = load_capture(root).views
    assert views[0].camera.lens == FISHEYE and views[2].camera.lens == Lens(k1=0.02)


@pytest.mark.parametrize("edit, message", [
    (lambda d: d.update(camera_model="EQUIRECTANGULAR"), r"top level: camera_model \"EQUIRECTANGULAR\" .* is not one dpi reads"),
    (lambda d: d["frames"][2].update(k4=0.1), r"frame 2 .*: k4 belongs to OPENCV_FISHEYE"),
    (lambda d: d.update(camera_model="PINHOLE", k1=0.1), r"top level: camera_model PINHOLE has no distortion, yet the file gives k1"),
    (lambda d: d.update(camera_model="OPENCV_FISHEYE", p1=0.1), r"top level: the fisheye model has no tangential terms"),
    (lambda d: d.update(k1="strong"), r"top level: k1 must be a number, got \"strong\""),
])
def test_a_lens_dpi_cannot_use_is_one_line(tmp_path, edit, message):
    root = make_capture(tmp_path / "cap")
    edit_transforms(root, edit)
    with pytest.raises(CaptureError, match=r"transforms.json: " + message):
        load_capture(root)


@pytest.mark.parametrize("lens", [BARREL, FISHEYE])
def test_projection_through_a_lens_matches_opencv(lens):
    camera = Camera(look_at((0.3, 0.4, 3.0), (0, 0, 0)), 64, 48, 50.0, 52.0, 31.0, 25.0, lens=lens)
    points = np.random.default_rng(0).uniform(-0.8, 0.8, (20, 3))
    ours, _ = camera.project(points)
    w2c = np.linalg.inv(camera.c2w)
    cam = points @ w2c[:3, :3].T + w2c[:3, 3]
    cv_points = np.stack([cam[:, 0], -cam[:, 1], -cam[:, 2]], -1)[:, None]  # OpenCV: y down, z forward
    if lens.fisheye:
        reference, _ = cv2.fisheye.projectPoints(cv_points, np.zeros(3), np.zeros(3), intrinsics(camera),
                                                 lens.coefficients())
    else:
        reference, _ = cv2.projectPoints(cv_points, np.zeros(3), np.zeros(3), intrinsics(camera), lens.coefficients())
    assert np.allclose(ours, reference[:, 0], atol=1e-6)


@pytest.mark.parametrize("lens", [BARREL, FISHEYE])
def test_undistortion_inverts_distortion(lens):
    camera = from_fov(np.eye(4), 96, 80, 60.0)
    y, x = np.mgrid[:80, :96]
    pinhole = (0.5 + 0.25 * np.sin(x / 5.0) * np.cos(y / 7.0)).astype(np.float32)
    back = undistort_image(distort_image(pinhole, camera, lens), camera, lens)
    centre = (slice(12, 68), slice(14, 82))
    assert np.abs(back[centre] - pinhole[centre]).max() < 0.02


def test_capture_json_keeps_the_lens():
    camera = cameras(1)[0]
    camera.lens = FISHEYE
    assert camera_from_json(json.loads(json.dumps(camera_to_json(camera)))).lens == FISHEYE


def test_the_capture_stage_writes_pinhole_views(tmp_path):
    """A capture whose photos came through a barrel lens: the capture stage undistorts images and masks once
    (OpenCV), so capture.json's views are pinhole views whose pixels are the undistorted photos'."""
    root = make_capture(tmp_path / "cap")
    original = {n: read_image(root / "images" / f"{n}.png") for n in ("r_0", "r_1")}
    edit_transforms(root, lambda d: d.update(k1=-0.12, k2=0.03))
    normalise_capture(root, tmp_path / "results" / "capture.json")
    views = read_capture_json(tmp_path / "results" / "capture.json").views
    assert all(v.camera.lens is None for v in views)
    assert all(v.image.parent == tmp_path / "results" / "undistorted" / "images" for v in views)
    lens = Lens(k1=-0.12, k2=0.03)
    for view in views[:2]:
        expected = undistort_image(original[view.name], view.camera, lens)
        assert np.allclose(read_image(view.image), expected, atol=1e-6)
        assert read_mask(view.mask).shape == (SIZE, SIZE)
    stamp = (tmp_path / "results" / "undistorted" / "images" / "r_0.exr").stat().st_mtime_ns
    normalise_capture(root, tmp_path / "results" / "capture.json")  # unchanged sources: the copies are reused
    assert (tmp_path / "results" / "undistorted" / "images" / "r_0.exr").stat().st_mtime_ns == stamp


def test_a_fitted_lens_is_kept_only_where_it_moves_pixels():
    from types import SimpleNamespace

    from dpi.preprocess.sfm import MIN_LENS_SHIFT_PX, _intrinsics, lens_shift_px

    # k1 alone moves the corner (r = half diagonal / f) by f k1 r^3
    focal, width, height = 500.0, 640, 480
    r = np.hypot(width / 2, height / 2) / focal
    assert np.isclose(lens_shift_px(Lens(k1=0.01), width, height, focal), focal * 0.01 * r**3)
    tiny = SimpleNamespace(model_name="SIMPLE_RADIAL", params=[focal, 320.0, 240.0, 1e-5], width=width, height=height)
    real = SimpleNamespace(model_name="SIMPLE_RADIAL", params=[focal, 320.0, 240.0, -0.05], width=width, height=height)
    assert _intrinsics(tiny)[4] is None and focal * 1e-5 * r**3 < MIN_LENS_SHIFT_PX
    assert _intrinsics(real) == (focal, focal, 320.0, 240.0, Lens(k1=-0.05))


def test_derived_cameras_with_a_lens_give_the_later_stages_pinhole_views(tmp_path):
    """Structure from motion fitted a lens (poses/transforms.json): the masks, geometry and inverse stages see
    the views undistorted, with pinhole cameras."""
    from dpi.capture import complete_capture
    from dpi.capture.cameras import write_transforms
    from dpi.capture.undistort import with_cameras
    from dpi.io.layout import SceneLayout

    root = make_capture(tmp_path / "cap", transforms=False)
    scene = SceneLayout(tmp_path / "results")
    normalise_capture(root, scene.capture_json)
    capture = read_capture_json(scene.capture_json)
    fitted = {v.name: c for v, c in zip(capture.views, cameras())}
    for camera in fitted.values():
        camera.lens = Lens(k1=-0.1)
    scene.poses["cameras"].parent.mkdir(parents=True, exist_ok=True)
    scene.poses["cameras"].write_text(json.dumps(write_transforms([(f"images/{n}.png", c) for n, c in fitted.items()])))
    scene.geometry["mesh_uv"].parent.mkdir(parents=True, exist_ok=True)
    scene.geometry["mesh_uv"].write_bytes(b"")  # the uv stage's output: only its path matters here
    with_cameras(capture, fitted, scene.undistorted_dir)  # as the poses stage does, once
    completed = complete_capture(capture, scene)
    assert all(v.camera.lens is None and v.image.parent == scene.undistorted_dir / "images" for v in completed.views)
    original = read_image(root / "images" / "r_0.png")
    expected = undistort_image(original, fitted["r_0"], Lens(k1=-0.1))
    assert np.allclose(read_image(completed.views[0].image), expected, atol=1e-6)
