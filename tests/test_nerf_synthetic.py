"""Captures in the NeRF-synthetic layout (transforms_{train,val,test}.json, RGBA cut-outs, file paths without an
extension) read through the one Capture: the given cameras and split kept, alpha as the masks; gt/envmap.hdr read;
and the workflow runs such a capture end to end with them."""

from __future__ import annotations

import csv
import json
import shutil

import cv2
import numpy as np
import pytest
from workflow_helpers import TINY_CONFIG, snakemake, write_config

from dpi.capture import CaptureError, inspect_capture, load_capture
from dpi.io.images import read_mask
from dpi.synth.capture import SynthConfig, make_synthetic_capture

TINY = {"views": 8, "width": 16, "height": 16, "spp": 4, "env_height": 8, "texture_size": 8, "seed": 2}


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """One synthetic scene written in dpi's layout and in NeRF-synthetic's."""
    root = tmp_path_factory.mktemp("layouts")
    ours = make_synthetic_capture(root / "dpi", SynthConfig(**TINY, image_format="png"), progress=False)
    nerf = make_synthetic_capture(root / "nerf", SynthConfig(**TINY, image_format="png", layout="nerf_synthetic"),
                                  progress=False)
    return ours, nerf


def test_the_given_cameras_split_and_alpha_masks_are_kept(pair):
    ours, nerf = (load_capture(root) for root in pair)
    assert inspect_capture(pair[1]) == {"cameras": True, "masks": True, "mesh": True, "mesh_has_uv": True}
    assert all(value == "given" for value in nerf.provenance.values())
    by_name = {v.name: v for v in ours.views}
    for view in nerf.views:
        split, name = view.name.split("_", 1)
        twin = by_name[name]
        assert (split == "test") == view.held_out == twin.held_out
        np.testing.assert_allclose(view.camera.c2w, twin.camera.c2w, atol=1e-6)
        assert view.camera.fx == pytest.approx(twin.camera.fx, rel=1e-6)
        assert (view.camera.width, view.camera.height) == (16, 16)
        assert (read_mask(view.mask) == read_mask(twin.mask)).mean() > 0.97  # alpha = coverage >= 0.5, 8-bit


def test_a_frame_without_its_image_is_named(pair, tmp_path):
    root = shutil.copytree(pair[1], tmp_path / "nerf")
    data = json.loads((root / "transforms_test.json").read_text())
    data["frames"][0]["file_path"] = "./test/missing"
    (root / "transforms_test.json").write_text(json.dumps(data))
    with pytest.raises(CaptureError, match=r"transforms_test.json: frame 0: no image './test/missing'"):
        load_capture(root)


def test_masks_named_after_the_images_match_the_split_views(pair, tmp_path):
    """masks/r_000.png beside train/r_000.png is the mask of view train_r_000."""
    root = shutil.copytree(pair[1], tmp_path / "nerf")
    shutil.copytree(pair[0] / "masks", root / "masks")
    capture = load_capture(root)
    assert all(view.mask is not None and view.mask.parent.name == "masks" for view in capture.views)
    assert {view.mask.stem for view in capture.views} == {view.name.split("_", 1)[1] for view in capture.views}


def test_a_test_split_alone_and_a_split_with_its_own_field_of_view_are_named(pair, tmp_path):
    only_test = shutil.copytree(pair[1], tmp_path / "only_test")
    (only_test / "transforms_train.json").unlink()
    with pytest.raises(CaptureError, match=r"transforms_test.json: every view is held out"):
        load_capture(only_test)
    wider = shutil.copytree(pair[1], tmp_path / "wider")
    data = json.loads((wider / "transforms_test.json").read_text())
    data["camera_angle_x"] *= 1.3
    (wider / "transforms_test.json").write_text(json.dumps(data))
    with pytest.raises(CaptureError, match=r"likely cause: focal length: the views that contradict their masks "
                                           r"\(test_r_\d+, \.\.\.\) have a [\d.]+ deg field of view"):
        load_capture(wider)


def test_an_alpha_stored_as_0_1_gets_the_scaling_hint(pair, tmp_path):
    root = shutil.copytree(pair[1], tmp_path / "nerf")
    for path in (root / "train").glob("*.png"):
        rgba = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        rgba[..., 3] = (rgba[..., 3] > 127).astype(np.uint8)
        cv2.imwrite(str(path), rgba)
    with pytest.raises(CaptureError, match=r"empty mask .*largest value is 1 of 255: masks stored as 0/1"):
        load_capture(root)


def test_a_view_in_a_fitted_and_the_held_out_split_is_refused(pair, tmp_path):
    """A test frame that names a train image would be fitted and scored as held out: refused, naming both splits."""
    root = shutil.copytree(pair[1], tmp_path / "nerf")
    train = json.loads((root / "transforms_train.json").read_text())
    test = json.loads((root / "transforms_test.json").read_text())
    test["frames"].append({**test["frames"][0], "file_path": train["frames"][0]["file_path"]})
    (root / "transforms_test.json").write_text(json.dumps(test))
    with pytest.raises(CaptureError, match=r"transforms_test.json: frame \d+: image .* is in the test split and in "
                                           r"the train split \(transforms_train.json\)"):
        load_capture(root)


def test_a_ground_truth_envmap_in_radiance_hdr_is_read(pair, tmp_path):
    root = shutil.copytree(pair[0], tmp_path / "hdr")
    env = np.random.default_rng(0).random((8, 16, 3)).astype(np.float32) + 0.1
    (root / "gt" / "envmap.exr").unlink()
    cv2.imwrite(str(root / "gt" / "envmap.hdr"), env[..., ::-1])
    capture = load_capture(root)
    assert capture.gt["envmap"].name == "envmap.hdr"


@pytest.mark.slow
def test_the_workflow_runs_a_nerf_synthetic_capture_with_its_cameras_and_split(tmp_path):
    config = {**TINY_CONFIG, "scenes": ["tiny_nerf"], "methods": ["none"], "samples": 1,
              "synthetic": {"tiny_nerf": {**TINY_CONFIG["synthetic"]["tiny"], "image_format": "png",
                                          "layout": "nerf_synthetic"}}}
    write_config(tmp_path / "config.yaml", config)
    snakemake(tmp_path, "results/eval/summary.csv")  # the format is the subject: up to the metrics
    capture = json.loads((tmp_path / "results" / "tiny_nerf" / "capture.json").read_text())
    assert capture["provenance"]["cameras"] == "given" and capture["provenance"]["masks"] == "given"
    assert not (tmp_path / "results" / "tiny_nerf" / "poses").exists()  # no structure from motion
    rows = list(csv.DictReader(open(tmp_path / "results" / "eval" / "summary.csv")))
    assert {r["method"] for r in rows} == {"init", "none"} and all(float(r["novel_psnr"]) > 5 for r in rows)
