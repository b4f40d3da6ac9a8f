"""The spread of samples (dpi.solve.spread) and its outputs: uncertainty maps, their summary and the calibration."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dpi.io.exr import read_exr, write_exr
from dpi.io.layout import decomposition_files
from dpi.light.envmap import texel_solid_angles
from dpi.solve.spread import albedo_std_map, calibration, log_std_map, mean_log_map, sphere_mean

H = 8


def bright_patch(factor: float) -> np.ndarray:
    """A uniform (H, 2H) map with a 2x2 patch `factor` times brighter (the median stays 1)."""
    env = np.ones((H, 2 * H, 3))
    env[2:4, 3:5] *= factor
    return env


def test_log_std_is_the_log_ratio_where_two_maps_differ_and_ignores_their_scale():
    spread = log_std_map([bright_patch(4.0), 10.0 * bright_patch(1.0)])
    assert spread[2:4, 3:5] == pytest.approx(np.full((2, 2), math.log(4.0) / math.sqrt(2)))
    spread[2:4, 3:5] = 0
    assert np.abs(spread).max() < 1e-9


def test_albedo_std_is_in_units_of_the_mean_albedo():
    flat = np.full((2, 2, 3), 0.3)
    pattern = 0.7 * np.array([[0.5, 1.5], [1.5, 0.5]])[..., None] * np.ones(3)  # over its mean: 0.5 / 1.5
    assert albedo_std_map([flat, pattern]) == pytest.approx(np.full((2, 2), 0.5 / math.sqrt(2)))


def test_one_sample_has_no_spread():
    with pytest.raises(ValueError, match="2 or more"):
        log_std_map([bright_patch(2.0)])


def test_sphere_mean_weights_texels_by_solid_angle():
    top = np.zeros((H, 2 * H))
    top[0] = 1.0
    assert sphere_mean(np.full((H, 2 * H), 0.3)) == pytest.approx(0.3)
    assert sphere_mean(top) == pytest.approx(float(texel_solid_angles(H)[0, 0] * 2 * H / (4 * math.pi)))


def test_calibration_is_a_quarter_when_the_truth_lies_midway_and_one_for_a_fair_draw():
    truth = bright_patch(1.0)
    assert calibration([bright_patch(math.e), bright_patch(1 / math.e)], truth) == pytest.approx(0.25)
    rng = np.random.default_rng(0)
    draws = [np.exp(rng.normal(0, 0.5, (H, 2 * H, 1))) * np.ones(3) for _ in range(41)]
    assert calibration(draws[1:], draws[0]) == pytest.approx(1.0, abs=0.1)


def test_mean_map_is_the_geometric_mean_after_each_maps_scale():
    assert mean_log_map([bright_patch(4.0), 10.0 * bright_patch(1.0)]) == pytest.approx(bright_patch(2.0))
    assert mean_log_map([bright_patch(math.e), bright_patch(1 / math.e)]) == pytest.approx(bright_patch(1.0))


def test_mean_maps_scores_are_the_truths_when_the_samples_straddle_it(tmp_path):
    from dpi.evaluation.metrics import env_metrics
    from dpi.evaluation.summary import spread_columns

    truth = bright_patch(3.0)
    write_exr(tmp_path / "truth.exr", truth.astype(np.float32))
    albedos = [np.full((2, 2, 3), 0.5)] * 2
    roughness = [np.full((2, 2, 3), 0.1), np.full((2, 2, 3), 0.5)]  # a mirror and a rough reading
    columns = spread_columns([truth * bright_patch(2.0), 5.0 * truth / bright_patch(2.0)], albedos, roughness,
                             tmp_path / "truth.exr")
    exact = env_metrics(truth, truth)
    assert columns["env_mean_psnr"] == pytest.approx(exact["env_psnr"])
    assert columns["env_mean_ssim"] == pytest.approx(exact["env_ssim"])
    assert columns["roughness_std"] == pytest.approx(0.4 / math.sqrt(2))
    assert spread_columns([truth, truth], albedos, roughness, None)["env_mean_psnr"] == "missing: no gt/envmap.exr"


def test_uncertainty_stage_writes_each_methods_maps_and_figure(tmp_path):
    from dpi.stages import Pipeline, StageJob, uncertainty_stage

    job = StageJob(Pipeline({"results_dir": str(tmp_path), "captures_dir": str(tmp_path / "captures")}), "scene")
    scene = job.paths
    for k, factor in enumerate((4.0, 1.0)):
        files = decomposition_files(scene.sample_dir("dps", k))
        write_exr(files["env"], bright_patch(factor).astype(np.float32))
        write_exr(files["albedo"], np.full((4, 4, 3), 0.2 * (k + 1), np.float32))
        write_exr(files["roughness"], np.full((4, 4, 3), 0.5 if k else 0.1, np.float32))
    uncertainty_stage(job, [("dps", [scene.sample_dir("dps", k) for k in range(2)])])
    env = read_exr(scene.uncertainty("dps")["env"])
    assert env.shape[:2] == (H, 2 * H) and float(env.max()) == pytest.approx(math.log(4.0) / math.sqrt(2), rel=1e-5)
    assert np.abs(read_exr(scene.uncertainty("dps")["albedo"])).max() < 1e-6  # 0.2 and 0.4: one albedo, two scales
    assert read_exr(scene.uncertainty("dps")["env_mean"]) == pytest.approx(bright_patch(2.0), rel=1e-5)
    assert read_exr(scene.uncertainty("dps")["roughness"])[..., 0] == pytest.approx(np.full((4, 4), 0.4 / math.sqrt(2)))
    assert scene.uncertainty_figure.stat().st_size > 1000
