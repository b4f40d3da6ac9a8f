"""Solvers: init lowers the loss, priors' known answers, NaN guards, seeded reproducibility, dip."""

import json
import math

import numpy as np
import pytest
import torch

from dpi.capture import load_capture
from dpi.io.settings import SettingsError
from dpi.render.renderer import RenderConfig
from dpi.solve.classic import ClassicConfig, balanced_weight, classic_sample
from dpi.solve.decomposition import Decomposition
from dpi.solve.dip import DeepImagePrior, DIPConfig, dip_sample, network_levels
from dpi.solve.init import (CLOSING_STEPS, READINGS, START_ALBEDO, InitConfig, closing_loss, is_glossy,
                            path_traced_init, sample_reading, starting_materials)
from dpi.solve.materials import MaterialTextures
from dpi.solve.optimize import AdamFit, FreeEnvMap, OptimizeConfig, fit
from dpi.solve.priors import chromaticity_penalty, global_norm_penalty, make_prior, smoothness_penalty
from dpi.solve.problem import InverseProblem, ProblemConfig, to_loss_space
from dpi.solve.trace import Trace


@pytest.fixture(scope="module")
def problem(tiny_capture):
    return InverseProblem(load_capture(tiny_capture), ProblemConfig(env_height=4, texture_size=8),
                          RenderConfig(spp=4, threads=2))


def test_priors_known_answers():
    grey = torch.full((4, 8, 3), 2.0)
    assert float(smoothness_penalty(grey)) == 0.0
    assert float(chromaticity_penalty(grey)) == pytest.approx(0.0, abs=1e-12)
    assert float(global_norm_penalty(grey, 2.0)) == pytest.approx(0.0, abs=1e-10)
    assert float(global_norm_penalty(grey, 2.0 * np.e)) == pytest.approx(1.0, rel=1e-5)
    red = grey.clone()
    red[..., 1:] = 0
    assert float(chromaticity_penalty(red)) == pytest.approx(2 / 3, rel=1e-6)
    assert make_prior("none", grey) is None
    with pytest.raises(ValueError, match="unknown prior"):
        make_prior("sharpness", grey)


def test_posterior_methods_start_from_the_init_roughness_its_median_metallic_and_a_grey_albedo():
    roughness = torch.tensor([0.35, 0.4, 0.5, 0.9]).reshape(2, 2, 1)
    metallic = torch.tensor([0.0, 0.0, 0.0, 0.8]).reshape(2, 2, 1)
    init = Decomposition(torch.ones(4, 8, 3), MaterialTextures(torch.rand(2, 2, 3), roughness.clone(), metallic.clone()))
    start = starting_materials(init)
    assert torch.all(start.albedo == START_ALBEDO)
    torch.testing.assert_close(start.roughness, roughness)
    assert torch.all(start.metallic == 0.0)  # the lower median of 4 texels
    torch.testing.assert_close(init.materials.roughness, roughness)  # the init is not touched


def test_a_glossy_init_keeps_its_roughness_and_metallic_textures():
    roughness = torch.tensor([0.05, 0.1, 0.5, 0.9]).reshape(2, 2, 1)  # 25th percentile 0.09 < 0.3
    metallic = torch.tensor([1.0, 1.0, 0.2, 0.0]).reshape(2, 2, 1)
    init = Decomposition(torch.ones(4, 8, 3), MaterialTextures(torch.rand(2, 2, 3), roughness, metallic))
    assert is_glossy(init.materials)
    start = starting_materials(init)
    torch.testing.assert_close(start.roughness, roughness)
    torch.testing.assert_close(start.metallic, metallic)
    assert torch.all(start.albedo == START_ALBEDO)


def test_the_view_loss_compares_log1p_images_so_a_glint_does_not_outweigh_the_rest(problem):
    image = problem.images[0].clone()
    mask = problem.masks[0]
    expected = ((torch.log1p(image * 1.1) - torch.log1p(image)).square() * mask[..., None]).sum() / (3 * mask.sum())
    torch.testing.assert_close(problem.view_loss(image * 1.1, 0), expected)
    glint, dim = image.clone(), image.clone()
    row, col = map(int, torch.nonzero(mask)[0])
    glint[row, col] = 100.0 * (1 + image[row, col])  # one pixel's sun missed by a factor 1.5 ...
    wrong_glint = glint.clone()
    wrong_glint[row, col] *= 1.5
    dim[mask] *= 0.5  # ... against every other pixel at half its radiance
    dim[row, col] = glint[row, col]

    def error(x: torch.Tensor, space=lambda image: image) -> float:
        return float(((space(x) - space(glint)).square() * mask[..., None]).sum())

    assert error(wrong_glint) > error(dim) and error(wrong_glint, to_loss_space) < error(dim, to_loss_space)


def test_balanced_weight_equalises_terms():
    assert balanced_weight(4.0, 2.0, 1.0) * 2.0 == pytest.approx(4.0)
    assert balanced_weight(4.0, 0.0, 0.5) == 2.0


def test_init_lowers_the_data_loss(problem):
    result = path_traced_init(problem, InitConfig(iterations=12, views_per_step=4, lr_env=0.1, reading="rough"),
                              seed=0, progress=False).kept
    losses = [s["loss"] for s in result.trace.steps]
    assert np.mean(losses[-3:]) < 0.8 * np.mean(losses[:3])
    assert torch.isfinite(result.env).all() and (result.env > 0).all()
    assert result.materials.roughness.min() >= 0.02


def test_nan_steps_are_skipped_and_counted(problem):
    calls = {"n": 0}

    def sometimes_nan(env):
        calls["n"] += 1
        return torch.tensor(float("nan")) if calls["n"] % 2 else env.mean()

    trace = Trace()
    log_env = torch.zeros(4, 8, 3)
    from dpi.solve.materials import MaterialTextures

    out_env, mats = fit(problem, log_env, MaterialTextures.constant(8), OptimizeConfig(iterations=4),
                        seed=0, trace=trace, prior=sometimes_nan, prior_weight=1.0, progress=False)
    assert trace.nan_skips == 2 and torch.isfinite(out_env).all()
    json.dumps(trace.steps, allow_nan=False)


def test_seeded_samples_reproduce_and_differ_across_seeds(problem):
    init = path_traced_init(problem, InitConfig(iterations=2, reading="rough"), seed=0, progress=False).kept
    cfg = ClassicConfig(optimize=OptimizeConfig(iterations=2, views_per_step=1))
    a = classic_sample(problem, "smoothness", init, cfg, seed=5, progress=False)
    b = classic_sample(problem, "smoothness", init, cfg, seed=5, progress=False)
    c = classic_sample(problem, "smoothness", init, cfg, seed=6, progress=False)
    # Dr.Jit accumulates gradients with parallel atomics, so reruns agree to float rounding only.
    torch.testing.assert_close(a.env, b.env, rtol=1e-3, atol=1e-4)
    torch.testing.assert_close(a.materials.albedo, b.materials.albedo, rtol=1e-3, atol=1e-4)
    assert (a.env - c.env).abs().max() > 1e-2
    assert a.trace.info["prior_weight"] > 0


def test_dip_network_is_seamless_seeded_and_shaped():
    cfg = DIPConfig(channels=8, code_channels=4)
    net = DeepImagePrior(8, torch.zeros(3), cfg, seed=1)
    with torch.no_grad():
        out = net()
        assert out.shape == (8, 16, 3) and torch.isfinite(out).all()
        # circular padding: rolling the code by a whole coarsest texel rolls the map, with no seam
        shift = 2 ** network_levels(8, cfg.depth)
        net.code = torch.roll(net.code, shift, dims=-1)
        torch.testing.assert_close(net(), torch.roll(out, shift, dims=1))
        torch.testing.assert_close(DeepImagePrior(8, torch.zeros(3), cfg, seed=1)(), out)
        assert (DeepImagePrior(8, torch.zeros(3), cfg, seed=2)() - out).abs().max() > 1e-3
    with pytest.raises(ValueError, match="even"):
        DeepImagePrior(5, torch.zeros(3), cfg, seed=1)
    with pytest.raises(ValueError, match="chanels: unknown DIPConfig setting; did you mean 'channels'"):
        DIPConfig.from_dict({"iterations": 3, "chanels": 8})
    assert DIPConfig.from_dict({"iterations": 3, "channels": 8}).optimize.iterations == 3


def test_dip_lowers_the_data_loss(problem):
    init = path_traced_init(problem, InitConfig(iterations=2, reading="rough"), seed=0, progress=False).kept
    cfg = DIPConfig(optimize=OptimizeConfig(iterations=15, views_per_step=4, lr_env=3e-2), channels=8,
                    code_channels=4, warmup_iterations=20)
    result = dip_sample(problem, init, cfg, seed=5, progress=False)
    losses = [s["data"] for s in result.trace.steps]
    assert np.mean(losses[-3:]) < 0.8 * np.mean(losses[:3])
    assert result.env.shape == init.env.shape and torch.isfinite(result.env).all() and (result.env > 0).all()
    assert result.materials.albedo.shape == init.materials.albedo.shape
    assert result.trace.info["prior_weight"] == 0.0 and result.trace.nan_skips == 0


def test_dip_samples_reproduce_and_differ_across_seeds(problem):
    init = path_traced_init(problem, InitConfig(iterations=2, reading="rough"), seed=0, progress=False).kept
    cfg = DIPConfig(optimize=OptimizeConfig(iterations=2, views_per_step=1), channels=8, code_channels=4,
                    warmup_iterations=5)
    a, b, c = (dip_sample(problem, init, cfg, seed=seed, progress=False) for seed in (5, 5, 6))
    torch.testing.assert_close(a.env, b.env, rtol=1e-3, atol=1e-4)
    torch.testing.assert_close(a.materials.albedo, b.materials.albedo, rtol=1e-3, atol=1e-4)
    assert (a.env - c.env).abs().max() > 1e-2


def test_a_saved_decomposition_loads_at_the_problems_size(problem, tmp_path):
    """save/load round trip in normalised units; a map and textures of another size come back at the problem's,
    the map's mean radiance kept (area average)."""
    env = torch.rand(8, 16, 3) + 0.5
    saved = Decomposition(env, MaterialTextures.constant(16, albedo=0.3, roughness=0.7))
    problem.save_decomposition(problem.to_solver_units(saved), tmp_path)
    loaded = problem.load_decomposition(tmp_path)
    assert loaded.env.shape == (4, 8, 3) and loaded.materials.albedo.shape[:2] == (8, 8)
    assert torch.allclose(problem.to_scene_units(loaded).env.mean((0, 1)), env.mean((0, 1)), rtol=1e-4)
    assert torch.allclose(loaded.materials.roughness, torch.full_like(loaded.materials.roughness, 0.7))


def test_a_fit_run_in_stretches_equals_one_uninterrupted_fit(problem):
    cfg = OptimizeConfig(iterations=6, views_per_step=2)
    start = MaterialTextures.constant(8, 0.5, 0.4, 0.1)
    log_env = torch.zeros(4, 8, 3)
    stretched = AdamFit(problem, FreeEnvMap(log_env), start, cfg, seed=3, trace=Trace())
    stretched.run(2, progress=False)
    stretched.run(6, progress=False)
    a_env, a_mats = stretched.finish()
    b_env, b_mats = fit(problem, log_env, start, cfg, seed=3, trace=Trace(), progress=False)
    torch.testing.assert_close(a_env, b_env, rtol=1e-4, atol=1e-5)
    for (name, x), (_, y) in zip(a_mats.items(), b_mats.items()):
        torch.testing.assert_close(x, y, rtol=1e-4, atol=1e-5, msg=name)
    assert [s["step"] for s in stretched.trace.steps] == list(range(6))


def test_the_init_fits_both_readings_and_keeps_the_one_most_samples_come_from(problem, monkeypatch):
    def init(reading: str):
        return path_traced_init(problem, InitConfig(iterations=6, reading=reading), seed=2, progress=False)

    alone = {name: init(name).kept for name in READINGS}  # each reading fitted alone: the same fit, bit for bit
    assert alone["rough"].trace.info["start"] == [0.5, 0.0] and alone["glossy"].trace.info["start"] == [0.1, 1.0]
    losses = {name: closing_loss(fit.trace) for name, fit in alone.items()}
    monkeypatch.setattr("dpi.solve.init.BOTH_FINISH", (0.0, math.inf))  # both always finish
    evidence = {"rough": 0.0, "glossy": 0.0}
    monkeypatch.setattr("dpi.solve.init.reading_evidence", lambda problem, fit, name, seed: evidence[name])
    for factor, kept, other in ((800.0, "glossy", None),  # the views favour the glossy reading beyond doubt
                                (-60.0, "rough", "glossy"),  # the rough one (the glossy one keeps e^-60 of the samples)
                                (0.5, "glossy", "rough")):  # about equally: both, in proportion
        evidence["glossy"] = factor
        result = init("auto")
        assert result.record["kept"] == kept and result.record["other"] == other
        assert result.record["log_bayes_factor"] == factor
        assert result.record["closing_loss"] == pytest.approx(losses, rel=1e-4)
        assert result.record["ratio"] == pytest.approx(losses["glossy"] / losses["rough"], rel=1e-4)
        torch.testing.assert_close(result.kept.env, alone[kept].env, rtol=1e-4, atol=1e-5)
        torch.testing.assert_close(result.kept.materials.roughness, alone[kept].materials.roughness, rtol=1e-4,
                                   atol=1e-5)
        assert result.kept.trace.info["readings"] is result.record
        assert (result.other is None) == (other is None)
        if other:
            torch.testing.assert_close(result.other.env, alone[other].env, rtol=1e-4, atol=1e-5)
            assert result.record["other_share"] == pytest.approx(1 / (1 + math.exp(abs(factor))), rel=1e-9)


def test_both_finished_readings_are_weighed_by_their_evidence(problem, monkeypatch):
    monkeypatch.setattr("dpi.solve.init.BOTH_FINISH", (0.0, math.inf))
    record = path_traced_init(problem, InitConfig(iterations=4), seed=2, progress=False).record
    assert math.isfinite(record["log_bayes_factor"])
    smaller = math.exp(-abs(record["log_bayes_factor"]))
    assert record["other_share"] == pytest.approx(smaller / (1 + smaller), abs=1e-300)


@pytest.mark.parametrize("behind", ["glossy", "rough"])
def test_the_reading_behind_half_way_stops_there(problem, monkeypatch, behind):
    band = (0.0, 0.0) if behind == "glossy" else (math.inf, math.inf)  # every half-way ratio above / below the band
    monkeypatch.setattr("dpi.solve.init.BOTH_FINISH", band)
    result = path_traced_init(problem, InitConfig(iterations=6), seed=2, progress=False)
    kept = "rough" if behind == "glossy" else "glossy"
    assert result.record["stopped"] == behind and result.record["kept"] == kept and result.other is None
    assert result.record["ratio"] is None and result.record["other_share"] == 0.0
    assert json.loads(json.dumps(result.record, allow_nan=False)) == result.record
    assert [s["step"] for s in result.kept.trace.steps] == list(range(6))
    assert result.kept.trace.info["reading"] == kept


@pytest.mark.parametrize("share", [0.0, 0.1, 0.25, 0.4, 0.5])
def test_sample_readings_start_with_the_kept_one_and_follow_the_share(share):
    readings = {"kept": "rough", "other": "glossy" if share else None, "other_share": share}
    drawn = [sample_reading(k, readings) for k in range(20)]
    assert drawn[0] == "rough"
    for n in range(1, 21):
        assert drawn[:n].count("glossy") == pytest.approx(n * share, abs=0.5)
    assert sample_reading(3, {}) == "rough"  # an init written before the readings


def test_closing_loss_is_the_mean_data_loss_of_the_last_steps():
    trace = Trace()
    for step in range(CLOSING_STEPS + 5):
        trace.record(step=step, data=100.0 if step < 5 else float(step % 2))
    trace.skip(CLOSING_STEPS + 5, "non-finite loss")
    assert closing_loss(trace) == pytest.approx(0.5)
    assert closing_loss(Trace()) == float("inf")


@pytest.mark.parametrize("start", [[], [0.5], [0.5, 1.5]])
def test_init_starts_must_be_a_roughness_metallic_pair_in_the_unit_range(start):
    with pytest.raises(SettingsError, match="start"):
        InitConfig.from_dict({"glossy_start": start})


def test_textures_with_a_nan_texel_are_refused_before_anything_is_written(tmp_path):
    materials = MaterialTextures.constant(4)
    materials.roughness[1, 2, 0] = float("nan")
    with pytest.raises(ValueError, match="refusing to save a non-finite roughness texture"):
        materials.save(tmp_path)
    assert not list(tmp_path.iterdir())
