"""Relighting scores (dpi.evaluation.relighting): known answers on images, and on a capture's own truth."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from dpi.capture import load_capture
from dpi.evaluation.metrics import PSNR_CAP
from dpi.evaluation.truth import true_materials
from dpi.evaluation.relighting import (RELIGHT_MAPS, RELIGHT_METRICS, channel_scaled,
                                       relight_held_out, relight_map, relight_metrics, relight_scores)
from dpi.light.envmap import top_energy_share
from dpi.render.renderer import RenderConfig
from dpi.solve.decomposition import Decomposition
from dpi.solve.materials import MaterialTextures
from dpi.solve.problem import InverseProblem, ProblemConfig


def test_per_channel_scale_is_least_squares_over_the_foreground():
    reference = np.random.default_rng(0).uniform(0.1, 4.0, (6, 6, 3))
    mask = np.zeros((6, 6), bool)
    mask[1:5, 1:5] = True
    estimate = reference * np.array([0.5, 2.0, 8.0])
    estimate[~mask] = 99.0  # the background does not enter the fit
    assert channel_scaled(estimate, reference, mask)[mask] == pytest.approx(reference[mask])


def test_the_truth_is_capped_and_a_per_channel_scaled_copy_scores_the_same():
    rng = np.random.default_rng(1)
    truth = rng.uniform(0, 20.0, (16, 16, 3))  # HDR: above 1 in places
    mask = rng.uniform(size=(16, 16)) > 0.3
    exact = relight_scores(truth, truth, mask)
    assert exact["relight_psnr_h"] == exact["relight_psnr_l"] == PSNR_CAP and exact["relight_ssim"] == pytest.approx(1)
    noisy = truth * rng.normal(1, 0.05, truth.shape)
    scaled = relight_scores(noisy * np.array([0.2, 3.0, 0.7]), truth, mask)
    assert scaled == pytest.approx(relight_scores(noisy, truth, mask))
    assert 10 < scaled["relight_psnr_h"] < PSNR_CAP


def test_relighting_maps_are_an_outdoor_sun_and_a_room():
    sun, room = relight_map("outdoor_sun"), relight_map("indoor")
    assert top_energy_share(sun) > 0.7 > 0.4 > top_energy_share(room)
    assert np.isfinite(sun).all() and np.isfinite(room).all() and sun.shape == (32, 64, 3)


@pytest.fixture(scope="module")
def problem(tiny_capture):
    return InverseProblem(load_capture(tiny_capture), ProblemConfig(env_height=4, texture_size=8),
                          RenderConfig(spp=4, threads=2))


def scores(problem, materials, spp=8, seed=3):
    decomposition = Decomposition(torch.ones(4, 8, 3), materials)
    return relight_metrics(problem, relight_held_out(problem, decomposition, spp, seed))


def test_the_true_materials_relight_exactly_and_grey_ones_do_not(problem):
    relit = relight_held_out(problem, Decomposition(torch.ones(4, 8, 3), MaterialTextures.constant(8)), 8, 3)
    assert len(relit) == 2 * len(RELIGHT_MAPS) * len(problem.held_out_ids)
    exact = scores(problem, true_materials(problem, 8))
    assert exact["relight_psnr_h"] == exact["relight_psnr_l"] == PSNR_CAP
    grey = scores(problem, MaterialTextures.constant(8, 0.5, 0.9, 0.0))
    assert all(np.isfinite(grey[name]) for name in RELIGHT_METRICS) and grey["relight_psnr_l"] < 40


def test_without_true_textures_the_scores_say_why(problem, monkeypatch):
    monkeypatch.setattr(problem.capture, "gt", {k: v for k, v in problem.capture.gt.items() if k != "metallic"})
    assert scores(problem, MaterialTextures.constant(8)) == {name: "missing: no gt/metallic.exr"
                                                             for name in RELIGHT_METRICS}
