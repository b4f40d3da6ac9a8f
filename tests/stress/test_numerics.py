"""Numerical stress: extreme HDR, black and saturated inputs, material extremes, scene scale, NaN renders."""

import pytest
import torch

from dpi.capture import load_capture
from dpi.capture.cameras import from_fov, look_at
from dpi.render.renderer import RenderConfig, Renderer
from dpi.solve.decomposition import Decomposition
from dpi.solve.materials import MaterialTextures
from dpi.solve.optimize import OptimizeConfig, fit
from dpi.solve.problem import InverseProblem, ProblemConfig
from dpi.solve.trace import Trace
from dpi.synth.shapes import blob, write_ply


@pytest.fixture(scope="module")
def sphere(tmp_path_factory, mi):
    path = tmp_path_factory.mktemp("stress") / "sphere.ply"
    write_ply(path, blob(resolution=24, bump=0.0))
    return path


def grad_of_render(renderer, env, mats):
    env = env.clone().requires_grad_(True)
    albedo = mats.albedo.clone().requires_grad_(True)
    image = renderer.render(env, albedo, mats.roughness, mats.metallic, view=0, seed=1)
    image.mean().backward()
    return image, env.grad, albedo.grad


def test_extreme_hdr_sun_next_to_dim_sky_stays_finite(sphere):
    cam = from_fov(look_at([0, 0, 4.0], [0, 0, 0]), 16, 16, 40.0)
    r = Renderer(sphere, [cam], 8, 8, RenderConfig(spp=8, threads=2))
    env = torch.full((8, 16, 3), 1e-3)
    env[2, 5] = 1e5
    image, g_env, g_alb = grad_of_render(r, env, MaterialTextures.constant(8))
    assert torch.isfinite(image).all() and torch.isfinite(g_env).all() and torch.isfinite(g_alb).all()


@pytest.mark.parametrize("roughness,metallic", [(0.02, 0.0), (1.0, 0.0), (0.02, 1.0), (1.0, 1.0)])
def test_material_extremes_render_finite_gradients(sphere, roughness, metallic):
    cam = from_fov(look_at([0, 0, 4.0], [0, 0, 0]), 16, 16, 40.0)
    r = Renderer(sphere, [cam], 8, 8, RenderConfig(spp=8, threads=2))
    mats = MaterialTextures.constant(8, albedo=0.0 if metallic else 1.0, roughness=roughness, metallic=metallic)
    image, g_env, g_alb = grad_of_render(r, torch.ones(8, 16, 3), mats)
    assert torch.isfinite(image).all() and torch.isfinite(g_env).all() and torch.isfinite(g_alb).all()


@pytest.mark.parametrize("scale", [1e-3, 1e3])
def test_huge_and_tiny_scene_scales(tmp_path, mi, scale):
    mesh = blob(resolution=16, bump=0.0)
    mesh.vertices = mesh.vertices * scale
    write_ply(tmp_path / "m.ply", mesh)
    cam = from_fov(look_at([0, 0, 4.0 * scale], [0, 0, 0]), 16, 16, 40.0)
    r = Renderer(tmp_path / "m.ply", [cam], 8, 8, RenderConfig(spp=4, threads=2))
    image, g_env, _ = grad_of_render(r, torch.ones(8, 16, 3), MaterialTextures.constant(8))
    assert torch.isfinite(g_env).all() and 0.05 < r.coverage(0).mean() < 0.9
    assert image.mean() > 0


@pytest.fixture(scope="module")
def problem(tiny_capture):
    return InverseProblem(load_capture(tiny_capture), ProblemConfig(env_height=4, texture_size=8),
                          RenderConfig(spp=4, threads=2))


@pytest.mark.parametrize("value", [0.0, 1.0])
def test_black_and_saturated_observations_fit_finite(problem, value):
    saved = [img.clone() for img in problem.images]
    try:
        for img in problem.images:
            img.fill_(value)
        log_env, mats = fit(problem, torch.zeros(4, 8, 3), MaterialTextures.constant(8), OptimizeConfig(iterations=3),
                            seed=0, trace=Trace(), progress=False)
        assert torch.isfinite(log_env).all() and all(torch.isfinite(t).all() for _, t in mats.items())
    finally:
        problem.images[:] = saved


def test_nan_render_is_skipped_and_never_written(problem, tmp_path, monkeypatch):
    monkeypatch.setattr(problem.renderer, "render", lambda *a, **k: torch.full((24, 24, 3), float("nan")))
    trace = Trace()
    log_env, mats = fit(problem, torch.zeros(4, 8, 3), MaterialTextures.constant(8), OptimizeConfig(iterations=3),
                        seed=0, trace=trace, progress=False)
    assert trace.nan_skips == 3 and torch.isfinite(log_env).all()
    with pytest.raises(ValueError, match="non-finite"):
        Decomposition(torch.full((4, 8, 3), float("nan")), mats).save(tmp_path / "out")
    assert not (tmp_path / "out" / "envmap.exr").exists()


def test_single_view_capture_has_no_novel_views_but_fits(tiny_capture, mi):
    from dpi.evaluation.sample_metrics import novel_view_metrics, render_held_out

    capture = load_capture(tiny_capture)
    capture.views = capture.views[:1]
    p = InverseProblem(capture, ProblemConfig(env_height=4, texture_size=8), RenderConfig(spp=4, threads=2))
    d = Decomposition(torch.ones(4, 8, 3), MaterialTextures.constant(8))
    assert novel_view_metrics(p, render_held_out(p, d, spp=4, seed=0))["novel_psnr"].startswith("missing")
    log_env, _ = fit(p, torch.zeros(4, 8, 3), MaterialTextures.constant(8), OptimizeConfig(iterations=2), seed=0,
                     trace=Trace(), progress=False)
    assert torch.isfinite(log_env).all()
