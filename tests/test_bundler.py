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


def capture_with_bundle(root, order=None, edit=None, points=True):
    """The tiny capture without transforms.json, its cameras in bundle.out (listed in `order` by list.txt when
    given); `edit` changes the file's lines (after the counts) before it is written."""
    from capture_helpers import NAMES, cameras, make_capture

    make_capture(root, transforms=False)
    cams = dict(zip(NAMES, cameras()))
    listed = order or sorted(NAMES)
    text = bundler_text([cams[n] for n in listed], (1.0, 1.0))
    if not points:
        text = text.replace(f"{len(listed)} 1\n", f"{len(listed)} 0\n").rsplit("\n", 4)[0] + "\n"
    lines = text.splitlines()
    if edit:
        lines = edit(lines)
    (root / "bundle.out").write_text("\n".join(lines) + "\n")
    if order:
        (root / "list.txt").write_text("".join(f"images/{n}.png 0 50\n" for n in order))
    return root, cams


def test_a_bundle_out_alone_gives_the_cameras_in_list_txts_order(tmp_path):
    from capture_helpers import NAMES

    from dpi.capture import load_capture
    from dpi.capture.bundler import capture_bundler_cameras

    order = list(reversed(NAMES))
    root, cams = capture_with_bundle(tmp_path / "s", order)
    capture = load_capture(root)
    assert capture.provenance["cameras"] == "derived"  # the poses stage reads it, as a COLMAP model
    read = capture_bundler_cameras(root, root / "bundle.out", {v.name: v.image for v in capture.views},
                                   capture.image_size)
    for name in NAMES:
        np.testing.assert_allclose(read[name].c2w, cams[name].c2w, atol=1e-9)


def test_the_poses_stage_reads_a_bundle_out_as_given(tmp_path):
    from capture_helpers import NAMES

    from dpi.capture.cameras import read_cameras
    from dpi.io.layout import poses_files
    from dpi.preprocess.derive import derive_poses, normalise_capture

    root, cams = capture_with_bundle(tmp_path / "s", list(reversed(NAMES)))
    normalise_capture(root, tmp_path / "out" / "capture.json")
    summary = derive_poses(tmp_path / "out" / "capture.json", tmp_path / "out" / "poses",
                           {"min_registered_fraction": 0.5})
    assert summary["cameras"] == "bundle.out"
    read = read_cameras(poses_files(tmp_path / "out" / "poses")["cameras"])
    for name in NAMES:  # the capture's mesh is in the file's frame: the cameras stay there
        np.testing.assert_allclose(read[name].c2w, cams[name].c2w, atol=1e-9)


def rotation_entry(camera: int, row: int, value: str):
    def edit(lines):
        words = lines[2 + 5 * camera + 1 + row].split()
        words[0] = value
        lines[2 + 5 * camera + 1 + row] = " ".join(words)
        return lines
    return edit


def focal(camera: int, value: str):
    def edit(lines):
        words = lines[2 + 5 * camera].split()
        words[0] = value
        lines[2 + 5 * camera] = " ".join(words)
        return lines
    return edit


def every_focal(value: str):
    def edit(lines):
        for c in range(4):
            lines = focal(c, value)(lines)
        return lines
    return edit


@pytest.mark.parametrize("edit, order, words", [
    (rotation_entry(1, 0, "nan"), None, r"camera 1 \(image 'r_1'\): its focal, distortion, rotation or translation "
                                        r"is not finite"),
    (focal(2, "-50"), None, r"camera 2 \(image 'r_2'\): focal length -50 px; it must be positive"),
    (rotation_entry(0, 1, "3"), None, r"camera 0 \(image 'r_0'\): its rotation is not orthonormal"),
    (every_focal("0"), None, "every camera's focal length is 0: Bundler placed none of them"),
    (lambda lines: lines[:12], None, "declares 4 cameras and 1 points but holds 10 lines"),
    (lambda lines: ["four cameras", *lines[2:]], None, "its first line is not the two counts"),
    (lambda lines: [lines[0], "3 1", *lines[2:-8], *lines[-3:]], None, "3 cameras for 4 images"),
    (None, ["r_0", "r_1", "r_2", "photo_9"], r"list.txt: line 4 names 'images/photo_9.png', which is not a photo"),
])
def test_a_bundle_out_that_cannot_be_used_is_named_at_validation(tmp_path, edit, order, words):
    from dpi.capture import CaptureError, load_capture

    if order and "photo_9" in order:
        root, _ = capture_with_bundle(tmp_path / "s")
        (root / "list.txt").write_text("".join(f"images/{n}.png\n" for n in order))
    else:
        root, _ = capture_with_bundle(tmp_path / "s", order, edit)
    with pytest.raises(CaptureError, match=words) as caught:
        load_capture(root)
    assert "bundle.out" in str(caught.value) or "list.txt" in str(caught.value)
    assert "\n" not in str(caught.value)


def test_a_bundle_out_without_points_reads(tmp_path):
    from dpi.capture import load_capture

    root, _ = capture_with_bundle(tmp_path / "s", points=False)
    assert read_bundler(root / "bundle.out").points.shape == (0, 3)
    load_capture(root)
