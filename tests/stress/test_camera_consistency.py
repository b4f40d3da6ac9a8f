"""Cameras that contradict the images, with known answers: on a copy of the tiny synthetic capture (a blob seen
by 5 cameras, exact masks), poses in the OpenCV convention, the camera list shifted by one, cameras twice as far
and a mesh twice as large each stop validation with one line naming the views, their IoU and the cause; without
masks the mesh must project into the images; every capture the tests use passes; after derived masks a given
mesh is checked too, and so are the cameras structure from motion returns."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Callable

import numpy as np
import pytest
import trimesh
from capture_helpers import edit_transforms, make_capture

from dpi.capture import CaptureError, load_capture
from dpi.capture.consistency import OPENCV_TO_GL, check_cameras, check_masks, overlaps, raycasting_scene, silhouettes
from dpi.io.images import read_mask, write_mask

VIEWS = ("r_000", "r_001", "r_002", "r_003", "r_004")


def matrices(change: Callable[[list[np.ndarray]], list[np.ndarray]]) -> Callable[[Path], None]:
    """An edit of transforms.json replacing the frames' camera-to-world matrices by change(matrices)."""
    def edit(root: Path) -> None:
        def apply(data: dict) -> None:
            new = change([np.array(f["transform_matrix"]) for f in data["frames"]])
            for frame, c2w in zip(data["frames"], new):
                frame["transform_matrix"] = c2w.tolist()
        edit_transforms(root, apply)
    return edit


def opencv(poses: list[np.ndarray]) -> list[np.ndarray]:
    """The poses as OpenCV writes them (camera looking down +z, y down)."""
    return [c2w @ OPENCV_TO_GL for c2w in poses]


def shifted(poses: list[np.ndarray]) -> list[np.ndarray]:
    """Each frame given the next frame's pose (the list off by one)."""
    return poses[1:] + poses[:1]


def twice_as_far(poses: list[np.ndarray]) -> list[np.ndarray]:
    """The camera positions doubled: poses in units half the mesh's."""
    out = [c2w.copy() for c2w in poses]
    for c2w in out:
        c2w[:3, 3] *= 2
    return out


def mesh_scaled(factor: float) -> Callable[[Path], None]:
    """The mesh scaled about the origin."""
    def edit(root: Path) -> None:
        mesh = trimesh.load(root / "mesh.ply", process=False)
        mesh.vertices *= factor
        mesh.export(root / "mesh.ply")
    return edit


def mesh_moved(offset: tuple[float, float, float]) -> Callable[[Path], None]:
    """The mesh translated by `offset`."""
    def edit(root: Path) -> None:
        mesh = trimesh.load(root / "mesh.ply", process=False)
        mesh.vertices += np.asarray(offset)
        mesh.export(root / "mesh.ply")
    return edit


def intrinsics(**values: float) -> Callable[[Path], None]:
    """Every frame's intrinsics set to `values` (fl_x, cx, ...)."""
    def edit(root: Path) -> None:
        edit_transforms(root, lambda data: [frame.update(values) for frame in data["frames"]])
    return edit


def inverted_masks(root: Path) -> None:
    """Every mask saved with object and background swapped."""
    for path in (root / "masks").iterdir():
        write_mask(path, ~read_mask(path))


def without_masks(edit: Callable[[Path], None]) -> Callable[[Path], None]:
    """`edit`, and the masks removed."""
    def both(root: Path) -> None:
        edit(root)
        shutil.rmtree(root / "masks")
    return both


REJECTED = {  # case: (edit of the capture, words of the message after the file)
    "opencv poses": (matrices(opencv), [
        "the cameras contradict the masks: the mesh's silhouette overlaps the mask with IoU < 0.7 in 5 of 5 views "
        "(r_000 0.00, r_001 0.00, r_002 0.00, r_003 0.00, r_004 0.00)",
        "likely cause: convention: the poses are OpenCV's", "diag(1, -1, -1, 1) every view fits (IoU >= 0.9"]),
    "list shifted by one": (matrices(shifted), [
        "in 5 of 5 views the mask fits another view's camera better than its own",
        "likely cause: order: the camera list is shifted by -1 against the images (r_000's mask fits the camera "
        "given for r_004, IoU 0.9"]),
    "cameras twice as far": (matrices(twice_as_far), [
        "IoU < 0.7 in 5 of 5 views (r_000 0.2", "likely cause: scale: the mesh's silhouette is 0.49x the mask's size"]),
    "mesh twice as large": (mesh_scaled(2.0), ["IoU < 0.7 in 5 of 5 views",
                                               "likely cause: scale: the mesh's silhouette is 2.2x the mask's size"]),
    "mesh far off to the side": (mesh_moved((1000.0, 0.0, 0.0)), ["likely cause: placement: "]),
    "mesh far above": (mesh_moved((0.0, 1000.0, 0.0)), ["likely cause: placement: "]),
    "focal length 1e12": (intrinsics(fl_x=1e12, fl_y=1e12), [
        "likely cause: focal length: r_000's fl_x 1e+12 px gives a 1.38e-09 deg field of view"]),
    "principal point outside": (intrinsics(cx=500.0), [
        "likely cause: principal point: r_000's (cx, cy) = (500,"]),
    "inverted masks": (inverted_masks, ["likely cause: mask polarity: the masks fit inverted"]),
    "opencv poses, no masks": (without_masks(matrices(opencv)), [
        "the cameras do not see the mesh: less than 50% of its vertices project into the image in 5 of 5 views "
        "(fraction inside: r_000 0.00,", "likely cause: convention: the poses are OpenCV's",
        "the mesh lies in every image (at least 100% of its vertices)"]),
}


@pytest.mark.parametrize("case", list(REJECTED))
def test_cameras_contradicting_the_images_stop_validation(tiny_capture, tmp_path, case):
    """One line, starting with transforms.json, naming the views with their IoU and the likely cause."""
    edit, words = REJECTED[case]
    root = shutil.copytree(tiny_capture, tmp_path / "scene")
    edit(root)
    with pytest.raises(CaptureError) as info:
        load_capture(root)
    message = str(info.value)
    assert message.startswith(f"{root / 'transforms.json'}: ") and "\n" not in message, message
    assert all(w in message for w in words), message


def test_the_synthetic_capture_fits_its_own_cameras(tiny_capture):
    """Measured: each view's mask against the mesh's silhouette from its own camera has IoU >= 0.98, and a
    neighbour's camera fits worse (the margin the order check uses)."""
    capture = load_capture(tiny_capture)
    cameras = check_cameras([v.camera for v in capture.views])
    masks = check_masks([read_mask(v.mask) for v in capture.views], (cameras[0].width, cameras[0].height))
    mesh = trimesh.load(capture.mesh, process=False)
    table = overlaps(masks, silhouettes(raycasting_scene(mesh.vertices, mesh.faces), cameras))
    own = np.diag(table)
    assert own.min() >= 0.98 and (table.max(1) == own).all(), table.round(3)


def test_helper_and_reference_layout_captures_pass(tmp_path):
    """The tests' own captures: the sphere with its disc masks, and without masks."""
    assert load_capture(make_capture(tmp_path / "with")).provenance["masks"] == "given"
    assert load_capture(make_capture(tmp_path / "without", masks=False)).provenance["masks"] == "derived"


def test_derived_masks_are_checked_against_a_given_mesh(tmp_path):
    """Photos of the unit sphere with cameras and a given mesh twice its size: validation passes (the mesh
    projects into the images), the derived masks then stop the masks stage with one line naming their folder."""
    from test_preprocess_masks import sphere_view

    from dpi.capture.cameras import from_fov, orbit, write_transforms
    from dpi.io.images import write_srgb
    from dpi.preprocess.derive import normalise_capture
    from dpi.preprocess.derive import derive_view_masks

    root = tmp_path / "capture"
    cameras = [from_fov(c2w, 32, 32, 40.0, f"v{i}") for i, c2w in enumerate(orbit(6, 6.0, (10.0, 35.0)))]
    for cam in cameras:
        write_srgb(root / "images" / f"{cam.name}.png", sphere_view(cam, "plain")[0])
    frames = write_transforms([(f"images/{c.name}.png", c) for c in cameras])
    frames["frames"][0]["held_out"] = True
    (root / "transforms.json").write_text(json.dumps(frames))
    trimesh.creation.icosphere(subdivisions=3, radius=2.0).export(root / "mesh.ply")
    normalise_capture(root, tmp_path / "capture.json")
    with pytest.raises(CaptureError) as info:
        derive_view_masks(tmp_path / "capture.json", tmp_path / "masks")
    message = str(info.value)
    assert message.startswith(f"{tmp_path / 'masks'}: the cameras contradict the masks") and "\n" not in message
    assert "likely cause: scale: the mesh's silhouette is 2" in message and "the masks are derived" in message


@pytest.mark.parametrize("frame_scale", [1.0, 2.0])
def test_cameras_from_structure_from_motion_are_checked_against_a_given_mesh(tmp_path, monkeypatch, frame_scale):
    """A capture with masks and a mesh but no cameras: the poses stage checks what structure from motion returns
    (stubbed: the true cameras, or the same in a frame twice the size) before writing it."""
    from dpi.preprocess import sfm
    from dpi.preprocess.derive import normalise_capture
    from dpi.preprocess.derive import derive_poses

    root = make_capture(tmp_path / "scene", transforms=False)
    (root / "scene.yaml").write_text("held_out: [r_3]\n")
    true = load_capture(make_capture(tmp_path / "truth"))
    poses = {v.name: v.camera for v in true.views}
    for camera in poses.values():
        camera.c2w[:3, 3] *= frame_scale
    model = sfm.SparseModel(poses, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, bool), {"registered": 4})
    monkeypatch.setattr(sfm, "run_sfm", lambda *args: model)
    monkeypatch.setattr(sfm, "normalise", lambda m: m)
    normalise_capture(root, tmp_path / "capture.json")
    if frame_scale == 1.0:
        assert derive_poses(tmp_path / "capture.json", tmp_path / "poses")["registered"] == 4
        return
    with pytest.raises(CaptureError) as info:
        derive_poses(tmp_path / "capture.json", tmp_path / "poses")
    message = str(info.value)
    assert message.startswith(f"{tmp_path / 'poses' / 'transforms.json'}: the cameras contradict the masks")
    assert "likely cause: scale" in message and "the cameras are structure from motion's" in message
    assert not (tmp_path / "poses" / "transforms.json").exists()
    assert json.loads((tmp_path / "poses" / "summary.json").read_text())["error"] == message
