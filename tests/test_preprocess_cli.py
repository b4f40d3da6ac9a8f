"""`dpi preprocess`: the stages a capture needs, as the workflow plans them, run without Snakemake."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from test_preprocess_masks import sphere_view

from dpi.capture.cameras import from_fov, orbit, write_transforms
from dpi.capture.consistency import mask_iou
from dpi.cli import main
from dpi.io.images import read_mask, write_srgb
from dpi.stages import needed_stages

FAST = {"preprocess": {"geometry": {"resolution": 48, "target_faces": 3000,
                                    "remesh_iterations": 1}},
        "problem": {"texture_size": 128}}


@pytest.mark.parametrize("given, stages", [
    ({"cameras": True, "masks": True, "mesh": True, "mesh_has_uv": True}, []),
    ({"cameras": False, "masks": True, "mesh": True, "mesh_has_uv": True}, ["poses"]),
    ({"cameras": True, "masks": True, "mesh": True, "mesh_has_uv": False}, ["uv"]),
    ({"cameras": True, "masks": False, "mesh": True, "mesh_has_uv": True}, ["poses", "masks"]),
    ({"cameras": False, "masks": False, "mesh": False, "mesh_has_uv": False}, ["poses", "masks", "geometry", "uv"]),
])
def test_needed_stages_follow_what_the_capture_gives(given, stages):
    assert needed_stages(given) == stages


@pytest.fixture()
def capture_with_cameras(tmp_path):
    """Photos of a sphere on a plain background with their cameras, no masks or mesh."""
    root = tmp_path / "capture"
    cameras = [from_fov(c2w, 64, 64, 40.0, f"v{i}") for i, c2w in enumerate(orbit(12, 4.0, (10.0, 35.0)))]
    truths = {}
    for cam in cameras:
        image, truths[cam.name] = sphere_view(cam, "plain")
        write_srgb(root / "images" / f"{cam.name}.png", image)
    (root / "transforms.json").write_text(json.dumps(write_transforms([(f"images/{c.name}.png", c) for c in cameras])))
    return root, truths


def folders(tmp_path, settings: dict | None = None) -> str:
    """A config file that reads captures from tmp_path and writes results under tmp_path/results."""
    config = tmp_path / "dirs.yaml"
    config.write_text(yaml.safe_dump({"captures_dir": str(tmp_path), "results_dir": str(tmp_path / "results"),
                                      **(settings or {})}))
    return str(config)


def test_dry_run_lists_the_needed_stages(capture_with_cameras, tmp_path, capsys):
    assert main(["preprocess", "capture", "--config", folders(tmp_path), "--dry-run"]) == 0
    lines = dict(line.split(None, 1) for line in capsys.readouterr().out.splitlines())
    assert lines["poses"] == "run" and lines["masks"] == "run" and lines["uv"] == "run"  # points for the masks
    assert not (tmp_path / "results").exists()


def test_preprocess_derives_masks_mesh_and_uvs_and_keeps_given_cameras(capture_with_cameras, tmp_path, capsys):
    from dpi.capture import complete_capture, read_capture_json
    from dpi.io.layout import SceneLayout

    _, truths = capture_with_cameras
    assert main(["preprocess", "capture", "--config", folders(tmp_path, FAST), "--threads", "1"]) == 0
    printed = capsys.readouterr().out
    assert "poses     derived" in printed and "uv        derived" in printed
    scene = SceneLayout(tmp_path / "results" / "capture")
    summary = json.loads(scene.poses["summary"].read_text())
    assert summary["cameras"] == "given" and summary["points"] == 0  # a plain sphere on a plain background
    ious = [mask_iou(read_mask(scene.masks / f"{name}.png"), truth) for name, truth in truths.items()]
    assert np.mean(ious) > 0.95, ious
    capture = complete_capture(read_capture_json(scene.capture_json), scene)
    assert capture.provenance == {"cameras": "given", "masks": "derived", "mesh": "derived", "uv": "derived"}
    assert capture.mesh == scene.geometry["mesh_uv"] and capture.mesh.is_file()


def test_capture_errors_are_one_message(tmp_path, capsys):
    assert main(["preprocess", "missing", "--config", folders(tmp_path)]) == 2
    assert "dpi preprocess: error:" in capsys.readouterr().err
