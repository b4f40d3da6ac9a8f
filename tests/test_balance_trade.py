"""A sample's broad albedo field (dpi.solve.dps.balance_trade): its size, its shape over the normals, and its life in
a proximal sample: on while the map settles, on dielectric texels only, the start's albedo back once the materials
move."""

from __future__ import annotations

import math

import numpy as np
import torch

from dpi.capture import load_capture
from dpi.render.renderer import RenderConfig
from dpi.solve.decomposition import Decomposition
from dpi.solve.dps import DPSConfig, posterior_steps, start_run
from dpi.solve.dps.balance_trade import balance_factor, log_spread, normal_texture
from dpi.solve.dps.proximal import MATERIAL_START
from dpi.solve.dps.start import sample_start_materials
from dpi.solve.init import InitConfig, path_traced_init
from dpi.solve.problem import InverseProblem, ProblemConfig
from tests.test_samplers import gaussian_prior


def test_the_spread_is_the_albedos_robust_log_std():
    """Log luminance N(log 0.4, 0.3^2) over the texels, one in twenty driven black: the spread stays near 0.3."""
    rng = np.random.default_rng(0)
    albedo = np.repeat(np.exp(rng.normal(math.log(0.4), 0.3, (64, 64, 1))), 3, axis=-1)
    albedo[:3] = 0.0
    chart = np.ones((64, 64), bool)
    assert abs(log_spread(albedo, chart) - 0.3) < 0.03
    assert float(np.log(np.maximum(albedo, 1e-4)).std()) > 1.0  # what a plain std would take for the albedo's spread
    assert log_spread(np.full((8, 8, 3), 0.5), np.ones((8, 8), bool)) == 0.0


def test_the_field_is_linear_in_the_normal_with_the_drawn_spread():
    """log of the factor is G n exactly; over many seeds G's entries have the spread as their std."""
    normals = np.random.default_rng(1).normal(size=(16, 16, 3))
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    flat = normals.reshape(-1, 3)
    draws = []
    for seed in range(200):
        log_factor = torch.log(balance_factor(normals, 0.5, seed)).double().numpy().reshape(-1, 3)
        directions, *_ = np.linalg.lstsq(flat, log_factor, rcond=None)
        np.testing.assert_allclose(flat @ directions, log_factor, atol=1e-5)
        draws.append(directions)
    assert abs(np.std(draws) - 0.5) < 0.03
    assert torch.equal(balance_factor(normals, 0.5, 3), balance_factor(normals, 0.5, 3))


def test_the_field_is_on_while_the_map_settles_and_off_once_the_materials_move(tiny_capture):
    problem = InverseProblem(load_capture(tiny_capture), ProblemConfig(env_height=4, texture_size=8),
                             RenderConfig(spp=4, threads=2))
    init = path_traced_init(problem, InitConfig(iterations=10, reading="rough"), seed=0, progress=False).kept
    normals, chart = normal_texture(problem, 8)
    assert np.allclose(np.linalg.norm(normals, axis=-1), 1.0, atol=1e-5)
    cfg = DPSConfig.from_dict({"steps": 5, "proximal": {"start_noise": 1.0}})
    run, state = start_run(problem, gaussian_prior(), init, cfg, seed=2)
    start = sample_start_materials(init).albedo
    first_move = math.ceil(MATERIAL_START * run.num_steps)
    for n, _ in enumerate(posterior_steps(run, state)):
        log_ratio = torch.log(state.materials.albedo.detach() / start)[torch.from_numpy(chart)]
        if n < first_move:  # held: the grey start times exp(G n)
            assert float(log_ratio.std()) > 0.05
        elif n == first_move:  # the start's albedo, moved by one Adam step
            assert float((state.materials.albedo.detach() - start).abs().max()) <= 1.1 * cfg.lr_albedo
            break
    off = DPSConfig.from_dict({"steps": 5, "proximal": {"start_noise": 1.0, "balance_trade": False}})
    run, state = start_run(problem, gaussian_prior(), init, off, seed=2)
    next(posterior_steps(run, state))
    assert torch.equal(state.materials.albedo.detach(), start)
    mixed = Decomposition(init.env, init.materials.detached())  # a glossy init, metal on the left half only
    mixed.materials.roughness.fill_(0.05)
    mixed.materials.metallic.fill_(0.0)
    mixed.materials.metallic[:, :4] = 1.0
    run, state = start_run(problem, gaussian_prior(), mixed, cfg, seed=2)
    next(posterior_steps(run, state))
    albedo, start = state.materials.albedo.detach(), sample_start_materials(mixed).albedo
    # metal, the colour of reflections that pin their light, away from the border texels the seams tie to others
    assert torch.equal(albedo[1:7, 1:4], start[1:7, 1:4])
    assert float(torch.log(albedo[:, 4:] / start[:, 4:])[torch.from_numpy(chart[:, 4:])].std()) > 0.05
