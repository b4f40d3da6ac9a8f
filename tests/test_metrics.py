"""Metric known answers: identical images, a known shift, scaled maps and albedos, and the summary's
set metrics (sigma2_invar across the illuminations of an object, init seconds, FID without weights)."""

import csv

import numpy as np
import pytest

from dpi.evaluation.metric_table import read_summary
from dpi.evaluation.metrics import PSNR_CAP, albedo_mse, env_metrics, psnr, ssim
from dpi.evaluation.perceptual import INCEPTION_WEIGHTS, WEIGHTS_ENV
from dpi.evaluation.summary import sample_rows, summarize, write_csv
from dpi.io.exr import write_exr
from dpi.solve.spread import sample_variance


def test_psnr_known_answers():
    a = np.full((8, 8, 3), 0.5)
    assert psnr(a, a) == PSNR_CAP  # an exact match is capped, never infinite
    assert psnr(a, a + 0.1) == pytest.approx(20.0)
    mask = np.zeros((8, 8), bool)
    mask[:2] = True
    b = a.copy()
    b[2:] = 0  # differences only outside the mask
    assert psnr(a, b, mask) == PSNR_CAP


def test_ssim_identical_is_one():
    a = np.random.default_rng(0).random((16, 32, 3))
    assert ssim(a, a) == pytest.approx(1.0)
    assert ssim(a, 1 - a) < 0.5


def test_env_metrics_ignore_a_global_scale():
    env = np.random.default_rng(1).random((8, 16, 3)).astype(np.float32) * 5
    m = env_metrics(3.0 * env, env)
    assert m["env_scale"] == pytest.approx(1 / 3, rel=1e-4)
    assert m["env_psnr"] > 60 and m["env_ssim"] == pytest.approx(1.0, abs=1e-4)


def test_env_metrics_resize_the_reference():
    env = np.ones((16, 32, 3), np.float32)
    assert env_metrics(np.ones((8, 16, 3), np.float32), env)["env_psnr"] == PSNR_CAP


def test_albedo_mse_aligns_each_channel():
    albedo = np.random.default_rng(2).random((8, 8, 3))
    mse, scales = albedo_mse(albedo * np.array([0.5, 2.0, 1.0]), albedo)
    assert mse == pytest.approx(0.0, abs=1e-20)
    np.testing.assert_allclose(scales, [2.0, 0.5, 1.0])


def test_sample_variance_known_answer():
    assert sample_variance([np.zeros(4), np.full(4, 2.0)]) == pytest.approx(2.0)
    assert sample_variance([np.ones(3)]) == 0.0


def toy_record(root, scene, method, albedo, obj=None, seconds=1.0):
    """An evaluation record of a sample with a constant env map and roughness and the given albedo."""
    sample_dir = root / scene / method
    write_exr(sample_dir / "envmap.exr", np.ones((4, 8, 3), np.float32))
    write_exr(sample_dir / "albedo.exr", albedo.astype(np.float32))
    write_exr(sample_dir / "roughness.exr", np.full(albedo.shape, 0.5, np.float32))
    record = {"scene": scene, "method": method, "sample": 0, "sample_dir": str(sample_dir), "gt_envmap": None,
              "metrics": {"sample_seconds": seconds}}
    return record if obj is None else {**record, "object": obj}


def test_summary_set_metrics(tmp_path, monkeypatch):
    monkeypatch.setenv(WEIGHTS_ENV, str(tmp_path / "no_weights"))
    flat = np.ones((2, 2, 3))
    pattern = 7.0 * np.array([[0.5, 1.5], [1.5, 0.5]])[..., None] * flat  # mean-normalised: 0.5 / 1.5
    records = [toy_record(tmp_path, "sunny", "m", flat, "cube"), toy_record(tmp_path, "cloudy", "m", pattern, "cube"),
               toy_record(tmp_path, "ball", "m", flat),  # no object key: its own scene
               toy_record(tmp_path, "sunny", "init", flat, "cube", seconds=12.0)]
    rows = {(r["scene"], r["method"]): r for r in summarize(records)}
    # two illuminations of the cube: per-texel variance (1 - 0.5)^2 / 2 = (1 - 1.5)^2 / 2 = 0.125
    assert rows[("sunny", "m")]["albedo_sigma2_invar"] == pytest.approx(0.125)
    assert rows[("cloudy", "m")]["albedo_sigma2_invar"] == pytest.approx(0.125)
    assert rows[("ball", "m")]["albedo_sigma2_invar"] == "missing: one illumination of object ball"
    assert rows[("sunny", "init")]["albedo_sigma2_invar"] == "missing: one illumination of object cube"
    assert rows[("sunny", "m")]["init_seconds"] == 12.0
    assert rows[("cloudy", "m")]["init_seconds"] == "missing: no init evaluation"
    fid = rows[("sunny", "m")]["env_fid"]
    assert fid.startswith("missing: ") and INCEPTION_WEIGHTS in fid
    per_sample = sample_rows(records, list(rows.values()))
    assert per_sample[1]["albedo_sigma2_invar"] == pytest.approx(0.125) and per_sample[1]["env_fid"] == fid


def test_summary_says_which_sampler_made_a_row(tmp_path, monkeypatch):
    monkeypatch.setenv(WEIGHTS_ENV, str(tmp_path / "no_weights"))
    flat = np.ones((2, 2, 3))
    records = [{**toy_record(tmp_path, "s", "dps", flat), "sampler": "proximal"},
               {**toy_record(tmp_path, "s", "dps", flat), "sample": 1, "sampler": "proximal"},
               toy_record(tmp_path, "s", "none", flat)]  # older evaluations have no sampler key
    rows = {r["method"]: r for r in summarize(records)}
    assert rows["dps"]["sampler"] == "proximal" and rows["none"]["sampler"] == ""
    # the spread columns: two identical samples agree everywhere, one sample has no spread, no truth no calibration
    assert rows["dps"]["env_log_std"] == 0 and rows["dps"]["albedo_std"] == 0
    assert rows["dps"]["env_calibration"] == "missing: no gt/envmap.exr"
    assert rows["none"]["env_log_std"] == "missing: one sample"
    assert [r["sampler"] for r in sample_rows(records, list(rows.values()))] == ["proximal", "proximal", ""]


def test_summary_csv_columns_stay_numeric(tmp_path, monkeypatch):
    """A missing metric is an empty cell with its reason in `notes`; read_summary gives the reason back."""
    monkeypatch.setenv(WEIGHTS_ENV, str(tmp_path / "no_weights"))
    flat = np.ones((2, 2, 3))
    rows = summarize([toy_record(tmp_path, "sunny", "m", flat, "cube"), toy_record(tmp_path, "ball", "m", flat)])
    path = tmp_path / "summary.csv"
    write_csv(path, rows)
    with open(path, newline="") as f:
        raw = list(csv.DictReader(f))
    for row in raw:
        for column, cell in row.items():
            if column not in ("scene", "method", "sampler", "object", "notes") and cell:
                float(cell)  # every non-empty metric cell is a number
    assert raw[0]["env_fid"] == "" and "env_fid: " in raw[0]["notes"]
    back = read_summary(path)
    assert back[0]["env_fid"] == rows[0]["env_fid"] and back[0]["albedo_sigma2_invar"].startswith("missing: one")
    assert "notes" not in back[0]


def test_balance_error_known_answer():
    """A map whose upper half is e^0.5 brighter than the truth's, relative to its lower half, is off by 0.25 in log
    at 2 rows after the global scale (solid-angle weights equal per hemisphere); a scaled copy is off by 0."""
    from dpi.evaluation.metrics import balance_error

    truth = np.random.default_rng(0).uniform(0.5, 2.0, (16, 32, 3)).astype(np.float32)
    assert balance_error(7.0 * truth, truth, 2) == pytest.approx(0.0, abs=1e-5)
    tilted = truth.copy()
    tilted[:8] *= np.exp(0.5)
    assert balance_error(tilted, truth, 2) == pytest.approx(0.25, abs=1e-4)
    assert balance_error(tilted, truth, 8) == pytest.approx(0.25, abs=1e-4)
