"""The differentiable renderer: gradients, env-map orientation, camera agreement, wrap columns."""

import numpy as np
import pytest
import torch

from dpi.capture.cameras import Camera, from_fov, look_at
from dpi.render.renderer import RenderConfig, Renderer
from dpi.solve.materials import MaterialTextures
from dpi.synth.shapes import blob, write_ply


@pytest.fixture(scope="module")
def sphere_ply(tmp_path_factory, mi):
    path = tmp_path_factory.mktemp("mesh") / "sphere.ply"
    write_ply(path, blob(resolution=48, bump=0.0))
    return path


def render(renderer, env, mats, view=0, seed=0, spp=None):
    return renderer.render(env, mats.albedo, mats.roughness, mats.metallic, view, seed, spp)


def test_env_gradient_satisfies_linearity(sphere_ply):
    """Radiance is linear in the map, so sum(env * dI/denv) == I for a fixed seed."""
    cam = from_fov(look_at([0, 0, 4.0], [0, 0, 0]), 16, 16, 40.0)
    r = Renderer(sphere_ply, [cam], 8, 8, RenderConfig(spp=16, threads=2))
    env = (torch.rand(8, 16, 3, generator=torch.Generator().manual_seed(0)) + 0.1).requires_grad_(True)
    mats = MaterialTextures.constant(8, albedo=0.6, roughness=0.4)
    image = render(r, env, mats)
    image.sum().backward()
    assert (env.grad * env.detach()).sum().item() == pytest.approx(image.sum().item(), rel=0.02)


def test_albedo_gradient_matches_finite_differences(sphere_ply):
    cam = from_fov(look_at([0, 0, 4.0], [0, 0, 0]), 16, 16, 40.0)
    r = Renderer(sphere_ply, [cam], 8, 8, RenderConfig(spp=64, threads=2))
    env = torch.full((8, 16, 3), 1.0)
    env[2:4, 3:6] = 8.0
    base = MaterialTextures.constant(8, albedo=0.5, roughness=0.6)

    def total(scale: torch.Tensor) -> torch.Tensor:
        mats = MaterialTextures(base.albedo * scale, base.roughness, base.metallic)
        return render(r, env, mats, seed=3).sum()

    scale = torch.tensor(1.0, requires_grad=True)
    total(scale).backward()
    h = 0.05
    with torch.no_grad():
        fd = (total(torch.tensor(1 + h)) - total(torch.tensor(1 - h))) / (2 * h)
    assert float(scale.grad) == pytest.approx(float(fd), rel=0.05)


def test_mirror_sphere_shows_the_bright_texel_where_expected(sphere_ply):
    """A mirror ball reflects a bright env texel at the point whose normal halves view and light."""
    from dpi.light.envmap import texel_directions

    H, size = 16, 64
    cam = from_fov(look_at([0, 0, 5.0], [0, 0, 0]), size, size, 30.0)
    r = Renderer(sphere_ply, [cam], H, 8, RenderConfig(spp=16, max_depth=2, threads=2))
    env = torch.full((H, 2 * H, 3), 0.01)
    row, col = 5, 21
    env[row, col] = 1000.0
    mats = MaterialTextures.constant(8, albedo=1.0, roughness=0.02, metallic=1.0)
    with torch.no_grad():
        image = render(r, env, mats).numpy().sum(-1)
    light = texel_directions(H)[row, col]
    to_camera = cam.center / np.linalg.norm(cam.center)
    normal = (light + to_camera) / np.linalg.norm(light + to_camera)
    expected, _ = cam.project(normal[None])  # unit sphere: the surface point is its normal
    y, x = np.unravel_index(image.argmax(), image.shape)
    assert np.hypot(x + 0.5 - expected[0, 0], y + 0.5 - expected[0, 1]) < 3.0


def test_silhouette_agrees_with_our_camera_model_off_centre(sphere_ply):
    """Rendered foreground == ray-cast coverage from dpi's own camera model, principal point shifted."""
    cam = Camera(look_at([0.5, 0.8, 4.0], [0, 0, 0]), 40, 30, 45.0, 45.0, 26.0, 12.0)
    r = Renderer(sphere_ply, [cam], 8, 8, RenderConfig(spp=16, threads=2))
    env = torch.ones(8, 16, 3)
    mats = MaterialTextures.constant(8, albedo=0.0, roughness=0.5)
    with torch.no_grad():
        image = render(r, env, mats).numpy().mean(-1)
    rendered_fg = image < 0.5  # black object on a white background
    covered = r.coverage(0) >= 0.5
    iou = (rendered_fg & covered).sum() / (rendered_fg | covered).sum()
    assert iou > 0.95


def test_shape_errors_name_the_tensor(sphere_ply):
    cam = from_fov(look_at([0, 0, 4.0], [0, 0, 0]), 8, 8, 40.0)
    r = Renderer(sphere_ply, [cam], 8, 8, RenderConfig(spp=1, threads=2))
    mats = MaterialTextures.constant(8)
    with pytest.raises(ValueError, match="env"):
        render(r, torch.ones(8, 8, 3), mats)
