"""Exposure invariance with known answers: the same capture at any absolute scale gives the same
decomposition up to that scale (env maps scale with it, materials do not), the same metrics, and
finite JSON; the metrics themselves do not depend on either map's scale; an exact match is capped."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from dpi.capture import load_capture
from dpi.evaluation.figures import display_env
from dpi.evaluation.metrics import PSNR_CAP, env_metrics
from dpi.evaluation.niqe import env_niqe
from dpi.evaluation.sample_metrics import evaluate_sample
from dpi.io.exr import read_exr, write_exr
from dpi.render.renderer import RenderConfig
from dpi.solve.decomposition import Decomposition
from dpi.solve.exposure import MIDDLE_GREY, capture_exposure
from dpi.solve.materials import MaterialTextures
from dpi.solve.problem import InverseProblem, ProblemConfig, SolveConfig
from dpi.solve.spread import normalized_env
from dpi.stages import capture_stage, evaluate_stage, init_stage, sample_stage
from stage_jobs import stage_job

SCALES = (1e-8, 1e-4, 1.0, 1e4, 1e8)
SETTINGS = SolveConfig(RenderConfig(spp=4, threads=1), ProblemConfig(env_height=4, texture_size=8))
RNG = np.random.default_rng(11)
ESTIMATE = RNG.lognormal(0.0, 1.0, (8, 16, 3)).astype(np.float32)
REFERENCE = (ESTIMATE * RNG.lognormal(0.0, 0.3, (8, 16, 3))).astype(np.float32)


@pytest.mark.parametrize("scale", SCALES)
def test_capture_exposure_scales_with_the_images(scale):
    """The exposure is a known statistic (foreground median luminance over 0.18) and scales with the images:
    foreground 6 pixels at 0.36, 7 at 0.9 and 3 black ones (ignored), so the median is 0.9."""
    images = [torch.full((4, 4, 3), 0.36), torch.full((4, 4, 3), 0.9)]
    images[1][0, :3] = 0.0
    masks = [torch.zeros(4, 4, dtype=torch.bool), torch.zeros(4, 4, dtype=torch.bool)]
    masks[0][:3, :2] = True
    masks[1][:, :1] = masks[1][:2, 1:4] = True
    exposure = capture_exposure([scale * im for im in images], masks, "c")
    assert exposure == pytest.approx(scale * 0.9 / MIDDLE_GREY, rel=1e-6)


@pytest.mark.parametrize("scale", SCALES)
def test_env_metrics_do_not_depend_on_either_maps_scale(scale):
    """env PSNR/SSIM are those of the unscaled pair whichever map is scaled; the alignment factor follows."""
    base = env_metrics(ESTIMATE, REFERENCE)
    both, estimate_only = env_metrics(scale * ESTIMATE, scale * REFERENCE), env_metrics(scale * ESTIMATE, REFERENCE)
    for m in (both, estimate_only):
        assert m["env_psnr"] == pytest.approx(base["env_psnr"], abs=1e-3)
        assert m["env_ssim"] == pytest.approx(base["env_ssim"], abs=1e-5)
    assert estimate_only["env_scale"] == pytest.approx(base["env_scale"] / scale, rel=1e-4)
    np.testing.assert_allclose(normalized_env(scale * ESTIMATE), normalized_env(ESTIMATE), atol=1e-5)
    np.testing.assert_allclose(display_env(scale * ESTIMATE, None), display_env(ESTIMATE, None), atol=1e-5)
    np.testing.assert_allclose(display_env(scale * ESTIMATE, REFERENCE), display_env(ESTIMATE, REFERENCE), atol=1e-5)


@pytest.mark.parametrize("scale", (1e-8, 1e8))
def test_env_niqe_does_not_depend_on_the_scale(scale):
    """NIQE scores the median-normalised map. NIQE itself is sensitive to rounding (scaling this map by
    1 + 1e-7 moves it 0.15 %), so float32 rounding of the scaled map may move it by a few tenths of a %."""
    env = np.repeat(np.repeat(ESTIMATE, 2, 0), 2, 1)
    assert env_niqe(scale * env) == pytest.approx(env_niqe(env), rel=1e-2)


def test_exact_match_reports_the_cap_and_says_so(tiny_capture):
    """The ground truth scored against itself: env PSNR is the cap, noted, and the metrics are valid JSON."""
    problem = InverseProblem(load_capture(tiny_capture), ProblemConfig(env_height=8, texture_size=8), SETTINGS.render)
    gt = torch.from_numpy(read_exr(tiny_capture / "gt" / "envmap.exr"))
    truth = problem.to_solver_units(Decomposition(gt, MaterialTextures.constant(8)))
    metrics = evaluate_sample(problem, truth, spp=4, seed=0, seconds=1.0)
    assert metrics["env_psnr"] == PSNR_CAP and metrics["env_ssim"] == pytest.approx(1.0)
    assert metrics["notes"]["capped"] == f"env_psnr: exact match, reported as the cap {PSNR_CAP:g} dB"
    json.dumps(metrics, allow_nan=False)


def scaled_copy(source: Path, target: Path, scale: float) -> Path:
    """The capture with its EXR images and ground-truth env map multiplied by `scale` (albedo etc. unchanged)."""
    shutil.copytree(source, target)
    for path in [*(target / "images").glob("*.exr"), target / "gt" / "envmap.exr"]:
        write_exr(path, scale * read_exr(path).astype(np.float64))
    return target


def run_chain(capture: Path, out: Path) -> dict:
    """capture -> init -> one `none` sample -> its evaluation, through the stage functions the rules call."""
    job = stage_job(capture, out, threads=1, render={"spp": 4}, evaluate={"spp": 4},
                    problem={"env_height": 4, "texture_size": 8, "resolution": None},
                    init={"iterations": 6, "views_per_step": 2},
                    method_params={"none": {"iterations": 4, "views_per_step": 2}})
    sample = replace(job, method="none")
    capture_stage(job)
    init_stage(job)
    sample_stage(sample)
    evaluate_stage(sample)
    return {"init_env": read_exr(job.sample_dir / "envmap.exr"), "env": read_exr(sample.sample_dir / "envmap.exr"),
            "albedo": read_exr(sample.sample_dir / "albedo.exr"),
            "log": json.loads((job.sample_dir / "log.json").read_text()),
            "metrics": json.loads(sample.evaluation.read_text())["metrics"]}


@pytest.fixture(scope="module")
def chains(tiny_capture, tmp_path_factory):
    """The same pipeline on the tiny capture at every scale in SCALES."""
    root = tmp_path_factory.mktemp("exposure")
    # every copy is scene `tiny` (in its own captures folder), so each chain draws the same seeds
    return {scale: run_chain(scaled_copy(tiny_capture, root / f"captures_{scale:g}" / "tiny", scale),
                             root / f"out_{scale:g}")
            for scale in SCALES}


@pytest.mark.parametrize("scale", [s for s in SCALES if s != 1.0])
def test_same_decomposition_up_to_scale_at_any_exposure(chains, scale):
    """Env maps scale with the capture, albedo does not, and every metric matches the unscaled run's."""
    ours, unit = chains[scale], chains[1.0]
    np.testing.assert_allclose(ours["init_env"] / scale, unit["init_env"], rtol=2e-3, atol=0)
    np.testing.assert_allclose(ours["env"] / scale, unit["env"], rtol=2e-3, atol=0)
    np.testing.assert_allclose(ours["albedo"], unit["albedo"], rtol=0, atol=2e-4)
    assert ours["log"]["info"]["exposure"]["scale"] == pytest.approx(scale * unit["log"]["info"]["exposure"]["scale"],
                                                                     rel=1e-5)
    for name in ("novel_psnr", "novel_ssim", "env_psnr", "env_ssim", "albedo_mse", "env_naturalness"):
        assert ours["metrics"][name] == pytest.approx(unit["metrics"][name], rel=1e-3), name
    # NIQE moves 0.15 % when a map moves by 1e-7 (test_env_niqe_does_not_depend_on_the_scale), and these maps agree
    # to 2e-3: measured up to 0.51 % apart (1e4 against 1, one thread), so the bound is the one that test uses
    assert ours["metrics"]["env_niqe"] == pytest.approx(unit["metrics"]["env_niqe"], rel=1e-2)
    assert ours["metrics"]["env_scale"] == pytest.approx(unit["metrics"]["env_scale"], rel=2e-3)


def test_unscaled_run_fits_in_normalised_units(chains):
    """The known answer behind the invariance: the init's map moved away from its start and is finite at 1e-8."""
    for scale, chain in chains.items():
        assert np.isfinite(chain["env"]).all() and chain["env"].min() > 0
        assert np.ptp(np.log(chain["init_env"] / scale)) > 0.05, scale
