"""Working resolution: images and masks area-downsampled once, cameras scaled with them, reused."""

import shutil

import numpy as np
import pytest

from dpi.capture import load_capture
from dpi.io.exr import read_exr
from dpi.io.images import read_image, read_mask, working_size
from dpi.capture.working import working_capture


def test_working_size_keeps_the_aspect_and_never_upsamples():
    assert working_size((4000, 3000), 128) == (128, 96)
    assert working_size((3000, 4000), 128) == (96, 128)
    assert working_size((64, 64), 128) == (64, 64)
    assert working_size((1600, 1200), None) == (1600, 1200)


def test_downsampled_capture_is_the_area_average_with_scaled_cameras(tiny_capture, tmp_path):
    capture = load_capture(tiny_capture)
    w, h = capture.image_size
    small = working_capture(capture, w // 2, tmp_path / "working")
    assert small.image_size == (w // 2, h // 2)
    for full, half in zip(capture.views, small.views):
        image = read_image(full.image)
        box = image.reshape(h // 2, 2, w // 2, 2, 3).mean(axis=(1, 3))  # exact 2x2 area average
        np.testing.assert_allclose(read_exr(half.image), box, rtol=1e-5, atol=1e-6)
        assert (half.camera.width, half.camera.height) == (w // 2, h // 2)
        assert half.camera.fx == pytest.approx(full.camera.fx / 2) and half.camera.cx == pytest.approx(full.camera.cx / 2)
        if full.mask is not None:
            coverage = read_mask(full.mask).reshape(h // 2, 2, w // 2, 2).mean(axis=(1, 3))
            assert (read_mask(half.mask) == (coverage > 0.5)).all()
        assert half.held_out == full.held_out
    # the same call again writes nothing: the copies are reused
    stamps = {p: p.stat().st_mtime_ns for p in (tmp_path / "working").rglob("*.exr")}
    working_capture(capture, w // 2, tmp_path / "working")
    assert stamps == {p: p.stat().st_mtime_ns for p in (tmp_path / "working").rglob("*.exr")}


def test_a_capture_no_larger_than_the_resolution_is_used_as_it_is(tiny_capture, tmp_path):
    capture = load_capture(tiny_capture)
    assert working_capture(capture, 4096, tmp_path / "w") is capture
    assert working_capture(capture, None, tmp_path / "w") is capture
    assert not (tmp_path / "w").exists()


def test_a_changed_source_image_is_resampled_again(tiny_capture, tmp_path):
    import shutil

    from dpi.io.exr import write_exr

    root = tmp_path / "cap"
    shutil.copytree(tiny_capture, root)
    capture = load_capture(root)
    w = capture.image_size[0]
    view = capture.views[0]
    before = read_exr(working_capture(capture, w // 2, tmp_path / "working").views[0].image)
    image = read_image(view.image)
    write_exr(view.image.with_suffix(".exr"), 2 * image) if view.image.suffix == ".exr" else pytest.skip("LDR views")
    after = read_exr(working_capture(load_capture(root), w // 2, tmp_path / "working").views[0].image)
    np.testing.assert_allclose(after, 2 * before, rtol=1e-5, atol=1e-6)


def test_evaluation_and_report_work_at_the_working_resolution(tiny_capture, tmp_path):
    from dataclasses import replace

    from dpi.capture import complete_capture, read_capture_json
    from dpi.evaluation.report import evaluated_capture, held_out_rerenders
    from dpi.stages import capture_stage, evaluate_stage
    from stage_jobs import stage_job

    size = load_capture(tiny_capture).image_size[0] // 2
    job = stage_job(tiny_capture, tmp_path / "results", render={"spp": 4}, evaluate={"spp": 8},
                    problem={"env_height": 8, "texture_size": 8, "resolution": size})
    scene = job.paths
    capture_stage(job)
    shutil.copytree(tiny_capture / "gt", scene.sample_dir("gt", 0))  # the truth, scored as a sample named gt
    evaluate_stage(replace(job, method="gt"))
    capture = evaluated_capture(scene, complete_capture(read_capture_json(scene.capture_json), scene), "gt")
    assert capture.image_size == (size, size) and (scene.working_dir / f"{size}x{size}").is_dir()
    (name, captured, (rerender,)), *_ = held_out_rerenders(scene, capture, ["gt"], 1.0)
    assert captured.shape[:2] == rerender.image.shape[:2] == (size, size)
    assert rerender.psnr > 20  # the ground truth (its map at 8 x 16) re-rendered at the working size matches
