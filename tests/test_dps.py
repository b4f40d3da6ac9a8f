"""Diffusion posterior sampling: schedules, gradient bound, and a full tiny run with NaN guards."""

import numpy as np
import pytest
import torch
import yaml

from dpi.capture import load_capture
from dpi.light.tonecurve import TONE_CURVES
from dpi.prior.diffusion import base_diffusion
from dpi.prior.sample import Prior
from dpi.prior.unet import SMALL_CONFIGS, UNetModel
from dpi.render.renderer import RenderConfig
from dpi.solve.dps import SAMPLERS, DPSConfig, dps_sample
from dpi.solve.dps.paper import rho_schedule, scale_to_bound
from dpi.solve.init import InitConfig, path_traced_init
from dpi.solve.problem import InverseProblem, ProblemConfig


def tiny_prior(height: int = 8) -> Prior:
    torch.manual_seed(0)
    model = UNetModel(SMALL_CONFIGS["tiny"]).eval()
    return Prior(model=model, diffusion=base_diffusion(1000, True), encoding=TONE_CURVES["outdoor"],
                 family="outdoor", height=height, median_target=0.1)


def test_rho_schedule_known_answer():
    rho = rho_schedule(10)
    assert np.allclose(rho[:5], 0.1) and np.allclose(rho[5:], np.linspace(0.1, 1.0, 6)[1:])


def test_yaml_booleans_name_the_sun_modes():
    """YAML 1.1 reads `sun: off` as False: the config means the mode, not a type error."""
    parsed = yaml.safe_load("sun: off\n")
    assert parsed == {"sun": False}
    assert DPSConfig.from_dict(parsed).sun.mode == "off"
    assert DPSConfig.from_dict(yaml.safe_load("sun: on\n")).sun.mode == "on"
    assert DPSConfig.from_dict(yaml.safe_load("sun: {mode: off, share: 0.4}\n")).sun.share == 0.4
    assert DPSConfig.from_dict({"sun": "auto"}).sun.mode == "auto"


def test_settings_are_grouped_and_each_key_is_checked_where_it_lives():
    cfg = DPSConfig.from_dict({"steps": 7, "proximal": {"inner_steps": 3, "transport": {"pixels": 512}},
                               "refine": {"iterations": 9}})
    assert (cfg.steps, cfg.sampler_settings.inner_steps, cfg.refine.iterations) == (7, 3, 9)
    assert cfg.proximal.transport.pixels == 512
    with pytest.raises(ValueError, match="inner_steps: unknown DPSConfig setting"):
        DPSConfig.from_dict({"inner_steps": 3})
    with pytest.raises(ValueError, match="proximal.transport.pixelz: unknown TransportConfig setting"):
        DPSConfig.from_dict({"proximal": {"transport": {"pixelz": 3}}})
    with pytest.raises(ValueError, match="proximal.transport.spp: must be a multiple of 2"):
        DPSConfig.from_dict({"proximal": {"transport": {"spp": 3}}})
    with pytest.raises(ValueError, match="proximal.start_noise: must be > 0, got 0"):
        DPSConfig.from_dict({"proximal": {"start_noise": 0}})
    with pytest.raises(ValueError, match="proximal.lr_mapp: unknown ProximalConfig setting; did you mean 'lr_map'"):
        DPSConfig.from_dict({"proximal": {"lr_mapp": 0.1}})
    with pytest.raises(ValueError, match="refine: must be a mapping"):
        DPSConfig.from_dict({"refine": 3})
    with pytest.raises(ValueError, match="^proximal: settings of the proximal sampler, which sampler paper does not "
                                         "use: remove them, or set sampler: proximal$"):
        DPSConfig.from_dict({"sampler": "paper", "proximal": {"inner_steps": 2}})


def test_a_glossy_init_changes_the_settings_in_one_place():
    """dpi.solve.dps.start.settings_for_init: a glossy init skips the map's solve, takes two updates a step and refines twice as long,
    with a freer per-texel polish where its map has the prior's rows (a coarser map gets the light polish);
    a rough init keeps the settings."""
    from dpi.solve.decomposition import Decomposition
    from dpi.solve.dps.start import settings_for_init
    from dpi.solve.materials import MaterialTextures

    cfg = DPSConfig.from_dict({"refine": {"iterations": 50, "views_per_step": 2}})
    env = torch.ones(4, 8, 3)
    glossy = settings_for_init(cfg, Decomposition(env, MaterialTextures.constant(8, roughness=0.1)), prior_rows=4)
    assert (glossy.refine.iterations, glossy.refine.views_per_step, glossy.refine.lr_texels) == (100, 2, 0.02)
    assert (glossy.proximal.map_solve, glossy.proximal.inner_steps) == (0, 2)
    assert glossy.proximal.transport.pixels == cfg.proximal.transport.pixels
    coarse = settings_for_init(cfg, Decomposition(env, MaterialTextures.constant(8, roughness=0.1)), prior_rows=8)
    assert (coarse.refine.iterations, coarse.refine.lr_texels) == (100, 0.005)
    assert settings_for_init(cfg, Decomposition(env, MaterialTextures.constant(8, roughness=0.8)), prior_rows=4) is cfg


def test_guidance_is_scaled_to_its_bound():
    g = torch.tensor([0.5, -0.25])
    assert torch.allclose(scale_to_bound(g, 0.1), torch.tensor([0.1, -0.05]))
    assert torch.equal(scale_to_bound(g * 0.1, 0.1), g * 0.1)


@pytest.fixture(scope="module")
def problem_and_init(tiny_capture):
    problem = InverseProblem(load_capture(tiny_capture), ProblemConfig(env_height=4, texture_size=8),
                             RenderConfig(spp=4, threads=2))
    return problem, path_traced_init(problem, InitConfig(iterations=2, reading="rough"), seed=0, progress=False).kept


def test_dps_run_is_finite_and_traced(problem_and_init, monkeypatch):
    problem, init = problem_and_init
    monkeypatch.setattr("dpi.solve.dps.loop.STRIP_FRAMES", 3)
    cfg = DPSConfig.from_dict({"sampler": "paper", "steps": 4, "refine": {"iterations": 2}})
    result = dps_sample(problem, tiny_prior(), init, cfg, seed=1, progress=False)
    d = result.decomposition
    assert d.env.shape == (4, 8, 3) and torch.isfinite(d.env).all() and (d.env >= 0).all()
    assert all(torch.isfinite(t).all() for _, t in d.materials.items())
    steps = d.trace.steps
    assert len(steps) == 4 and [s["rho"] for s in steps][0] == pytest.approx(0.1)
    assert all(s["guidance_max"] is not None and s["guidance_max"] > 0 for s in steps)
    assert len(result.snapshots) == 3 and d.trace.info["radiance_scale"] > 0


def test_nan_network_output_is_skipped_not_propagated(problem_and_init):
    problem, init = problem_and_init
    prior = tiny_prior()
    calls = {"n": 0}
    real = prior.model.forward

    def flaky(x, t):
        calls["n"] += 1
        out = real(x, t)
        return out * float("nan") if calls["n"] == 2 else out

    prior.model.forward = flaky
    for sampler in SAMPLERS:
        calls["n"] = 0
        cfg = DPSConfig.from_dict({"sampler": sampler, "steps": 4, "refine": {"iterations": 1}})
        result = dps_sample(problem, prior, init, cfg, seed=2, progress=False)
        assert result.decomposition.trace.nan_skips == 1, sampler
        assert torch.isfinite(result.decomposition.env).all()


def test_sds_ablation_runs_finite(problem_and_init):
    from dpi.solve.sds import SDSConfig, sds_sample

    problem, init = problem_and_init
    d = sds_sample(problem, tiny_prior(), init, SDSConfig(iterations=3), seed=3, progress=False)
    assert d.env.shape == (4, 8, 3) and torch.isfinite(d.env).all()
    assert len(d.trace.steps) == 3 and d.trace.info["sds_weight"] > 0
