"""A capture that brings its COLMAP model (sparse/0, text or binary): read with pycolmap as given instead of
running structure from motion, checked at validation, its sparse points kept for the masks stage."""

from __future__ import annotations

import json
import struct

import numpy as np
import pycolmap
import pytest
from capture_helpers import NAMES, cameras, make_capture
from colmap_helpers import write_text_model

from dpi.capture import CaptureError, load_capture
from dpi.capture.cameras import read_cameras
from dpi.io.layout import poses_files
from dpi.preprocess.derive import derive_poses, normalise_capture
from dpi.preprocess.sfm import read_points_ply

GIVEN = dict(zip(NAMES, cameras()))


def colmap_capture(root, binary=False, mesh=True):
    """A capture without transforms.json whose cameras are a COLMAP model in sparse/0."""
    make_capture(root, transforms=False, mesh=mesh)
    write_text_model(root / "sparse" / "0", {n: GIVEN[n] for n in NAMES}, suffix=".png")
    if binary:
        model = pycolmap.Reconstruction(str(root / "sparse" / "0"))
        for f in (root / "sparse" / "0").iterdir():
            f.unlink()
        model.write_binary(str(root / "sparse" / "0"))
    return root


@pytest.mark.parametrize("binary", [False, True])
def test_the_poses_stage_reads_the_model_as_given(tmp_path, binary):
    root = colmap_capture(tmp_path / "s", binary)
    normalise_capture(root, tmp_path / "out" / "capture.json")
    summary = derive_poses(tmp_path / "out" / "capture.json", tmp_path / "out" / "poses",
                          {"min_registered_fraction": 0.5})
    assert summary["source"].endswith("sparse/0") and summary["registered"] == len(NAMES)
    read = read_cameras(poses_files(tmp_path / "out" / "poses")["cameras"])
    for name in NAMES:  # the capture's mesh is in the model's frame, so the cameras stay there
        np.testing.assert_allclose(read[name].c2w, GIVEN[name].c2w, atol=1e-9)
        assert read[name].fx == pytest.approx(GIVEN[name].fx)
    points, _, on_object = read_points_ply(poses_files(tmp_path / "out" / "poses")["points"])
    assert len(points) > 50 and on_object.all()
    assert json.loads(poses_files(tmp_path / "out" / "poses")["summary"].read_text())["points"] >= len(points)


def test_without_a_mesh_the_model_is_brought_into_dpis_frame_rigidly(tmp_path):
    root = colmap_capture(tmp_path / "s", mesh=False)
    normalise_capture(root, tmp_path / "out" / "capture.json")
    derive_poses(tmp_path / "out" / "capture.json", tmp_path / "out" / "poses", {"min_registered_fraction": 0.5})
    read = read_cameras(poses_files(tmp_path / "out" / "poses")["cameras"])
    a, b = (read[n].c2w[:3, :3].T @ read[NAMES[0]].c2w[:3, :3] for n in NAMES[1:3])
    c, d = (GIVEN[n].c2w[:3, :3].T @ GIVEN[NAMES[0]].c2w[:3, :3] for n in NAMES[1:3])
    np.testing.assert_allclose(a, c, atol=1e-6)  # relative poses as given
    np.testing.assert_allclose(b, d, atol=1e-6)


def test_an_incomplete_or_foreign_model_is_named_at_validation(tmp_path):
    root = colmap_capture(tmp_path / "s")
    (root / "sparse" / "0" / "images.txt").unlink()
    with pytest.raises(CaptureError, match=r"sparse/0: COLMAP model without images.txt"):
        load_capture(root)
    other = colmap_capture(tmp_path / "t")
    write_text_model(other / "sparse" / "0", {f"photo_{i}": c for i, c in enumerate(GIVEN.values())})
    with pytest.raises(CaptureError, match="registers none of the images in images/"):
        load_capture(other)


def edit_first_camera(root, edit):
    """cameras.txt with its first camera's fields (id, model, width, height, params...) changed by `edit`."""
    path = root / "sparse" / "0" / "cameras.txt"
    lines = path.read_text().splitlines()
    lines[0] = " ".join(edit(lines[0].split()))
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("edit, cause", [
    (lambda f: [*f[:4], "0", *f[5:]], r"camera 1 \(of image 'r_0.png'\): focal length 0 px; it must be positive"),
    (lambda f: [*f[:4], "-100", *f[5:]], "focal length -100 px; it must be positive"),
    (lambda f: [*f[:4], "nan", *f[5:]], "camera 1: its parameters are not finite"),
    (lambda f: [f[0], "FOV", *f[2:], "0.5"], "COLMAP camera model FOV is not read by dpi"),
    (lambda f: [*f[:6], "1e6", f[7]], r"principal point \(1e\+06, .*\) px lies outside"),
    (lambda f: [f[0], f[1], str(2 * int(f[2])), str(2 * int(f[3])), *f[4:]],
     r"camera 1 \(of image 'r_0.png'\) is \d+ x \d+ px but the images are"),
])
def test_a_models_unusable_camera_is_named_at_validation(tmp_path, edit, cause):
    """Intrinsics are checked before the poses stage runs: one line naming the model, the camera and the cause."""
    root = colmap_capture(tmp_path / "s")
    edit_first_camera(root, edit)
    with pytest.raises(CaptureError, match=cause) as info:
        load_capture(root)
    assert "sparse/0" in str(info.value) and "\n" not in str(info.value)


def test_a_truncated_binary_model_and_a_nan_pose_are_named(tmp_path):
    root = colmap_capture(tmp_path / "s", binary=True)
    images = root / "sparse" / "0" / "images.bin"
    images.write_bytes(images.read_bytes()[:100])
    with pytest.raises(CaptureError, match=r"sparse/0: not a readable COLMAP model .*pycolmap: \w+"):
        load_capture(root)
    other = colmap_capture(tmp_path / "t")
    path = other / "sparse" / "0" / "images.txt"
    lines = path.read_text().splitlines()
    lines[0] = " ".join([lines[0].split()[0], "nan", *lines[0].split()[2:]])
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(CaptureError, match=r"sparse/0: image 'r_\d+\.png': its pose is not finite"):
        load_capture(other)
    binary = colmap_capture(tmp_path / "u", binary=True)  # pycolmap would read its NaN as another rotation
    path = binary / "sparse" / "0" / "images.bin"
    data = bytearray(path.read_bytes())
    struct.pack_into("<d", data, 8 + 4, float("nan"))  # the first image's qw
    path.write_bytes(bytes(data))
    with pytest.raises(CaptureError, match=r"sparse/0: image 'r_0\.png': its pose is not finite .* in images\.bin"):
        load_capture(binary)
    path = binary / "sparse" / "0" / "cameras.bin"
    data = bytearray(path.read_bytes())
    struct.pack_into("<d", data, 8 + 24, float("inf"))  # the first camera's first parameter
    path.write_bytes(bytes(data))
    with pytest.raises(CaptureError, match=r"sparse/0: camera \d+: its parameters are not finite .* in cameras\.bin"):
        load_capture(binary)


@pytest.mark.slow
def test_the_workflow_runs_a_colmap_model_capture_with_its_cameras(tmp_path):
    """A synthetic capture whose transforms.json is replaced by a COLMAP text model of its cameras (and its
    mesh in the model's frame) runs end to end: the poses stage reads the model, no structure from motion."""
    from workflow_helpers import TINY_CONFIG, snakemake, write_config

    from dpi.synth.capture import SynthConfig, make_synthetic_capture

    root = make_synthetic_capture(tmp_path / "captures" / "colmap",
                                  SynthConfig.from_dict(TINY_CONFIG["synthetic"]["tiny"]), progress=False)
    (root / ".synth.json").unlink()
    given = read_cameras(root / "transforms.json")
    held = [n for n, c in given.items() if c.extras.get("held_out")]
    (root / "transforms.json").unlink()
    (root / "scene.yaml").write_text(f"held_out: {held}\n")
    write_text_model(root / "sparse" / "0", given, suffix=".exr")
    config = {**TINY_CONFIG, "scenes": ["colmap"], "synthetic": {}, "methods": ["none"], "samples": 1,
              "preprocess": {"sfm": {"min_registered_fraction": 0.5}}}
    write_config(tmp_path / "config.yaml", config)
    snakemake(tmp_path, "results/eval/summary.csv")  # the format is the subject: up to the metrics
    summary = json.loads((tmp_path / "results" / "colmap" / "poses" / "summary.json").read_text())
    assert summary["source"].endswith("sparse/0") and "match_s" not in summary
    read = read_cameras(tmp_path / "results" / "colmap" / "poses" / "transforms.json")
    for name, camera in given.items():
        np.testing.assert_allclose(read[name].c2w, camera.c2w, atol=1e-6)
    assert (tmp_path / "results" / "eval" / "summary.csv").is_file()
