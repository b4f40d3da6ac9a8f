"""The recorded light transport: Mitsuba's envmap and bitmap lookups exactly, images under other maps and albedos
against the path tracer, its gradients against Dr.Jit's, the two halves' unbiased data
term, and the normal equations of map and albedo against it."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from dpi.capture import load_capture
from dpi.render.renderer import RenderConfig, texture_plugin
from dpi.solve.materials import MaterialTextures
from dpi.solve.problem import InverseProblem, ProblemConfig
from dpi.solve.transport import TransportConfig, guide_map, record_transport, record_view
from dpi.solve.transport.record import texel_weights, texture_weights, transport_pixels

HEIGHT, SIZE = 8, 8


@pytest.fixture(scope="module")
def problem(tiny_capture):
    return InverseProblem(load_capture(tiny_capture), ProblemConfig(env_height=HEIGHT, texture_size=SIZE),
                          RenderConfig(spp=16, threads=2))


def random_map(seed: int, spread: float = 1.0) -> torch.Tensor:
    return torch.exp(spread * torch.randn(HEIGHT, 2 * HEIGHT, 3, generator=torch.Generator().manual_seed(seed)))


def random_albedo(seed: int) -> torch.Tensor:
    return 0.1 + 0.8 * torch.rand(SIZE, SIZE, 3, generator=torch.Generator().manual_seed(seed))


def materials() -> MaterialTextures:
    mats = MaterialTextures.constant(SIZE, 0.6, 0.35, 0.2)
    mats.roughness = mats.roughness * torch.linspace(0.8, 1.2, SIZE)[:, None, None]
    return mats


def test_texel_weights_are_mitsubas_envmap_lookup(mi):
    import drjit as dr

    env = random_map(0).numpy().astype(np.float32)
    emitter = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(env)})
    d = np.random.default_rng(1).normal(size=(5000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    si = dr.zeros(mi.SurfaceInteraction3f, len(d))
    si.wi = mi.Vector3f(*(-d.T))
    expected = np.asarray(emitter.eval(si)).T
    index, weight = texel_weights(d, HEIGHT)
    assert np.allclose(weight.sum(1), 1) and (weight >= 0).all()
    np.testing.assert_allclose((env.reshape(-1, 3)[index] * weight[..., None]).sum(1), expected, rtol=1e-4, atol=1e-5)


def test_texture_weights_are_mitsubas_bitmap_lookup(mi):
    import drjit as dr

    data = random_albedo(2).numpy()
    texture = mi.load_dict(texture_plugin(data))
    uv = np.random.default_rng(3).uniform(-0.05, 1.05, size=(4000, 2))  # past the edges too (clamped)
    si = dr.zeros(mi.SurfaceInteraction3f, len(uv))
    si.uv = mi.Point2f(*uv.T.astype(np.float32))
    expected = np.asarray(texture.eval(si)).T
    index, weight = texture_weights(uv, SIZE)
    np.testing.assert_allclose((data.reshape(-1, 3)[index] * weight[..., None]).sum(1), expected, rtol=1e-4,
                               atol=1e-5)


def render_mean(problem, env, mats, view, seeds=range(3), spp=256) -> np.ndarray:
    with torch.no_grad():
        return np.mean([problem.render(env, mats, view, seed=s, spp=spp).numpy() for s in seeds], axis=0)


@pytest.fixture(scope="module")
def recorded(problem):
    """One view's transport at many samples (the image tests) under materials()."""
    view = problem.train_ids[0]
    settings = TransportConfig(spp=128)
    return view, record_view(problem, view, materials(), guide_map(random_map(0)), settings, seed=3)


def test_images_under_other_maps_and_albedos_like_the_path_tracer(problem, recorded):
    view, t = recorded
    mask = problem.masks[view].numpy()
    roughness = materials().roughness
    for seed, spread in ((5, 1.0), (6, 2.0)):  # maps the recording's guide never saw, up to e^4 dynamic range
        env, albedo = random_map(seed, spread), random_albedo(seed)
        mats = MaterialTextures(albedo, roughness, materials().metallic)
        cached = t.image(env.numpy(), albedo.numpy())[mask]
        reference = render_mean(problem, env, mats, view)[mask]
        independent = render_mean(problem, env, mats, view, seeds=[11], spp=256)[mask]
        noise = np.sqrt(np.mean((independent - reference) ** 2))
        assert abs(cached.mean() - reference.mean()) < 0.02 * reference.mean()
        assert np.sqrt(np.mean((cached - reference) ** 2)) < 1.5 * noise  # within the path tracer's own noise


def sunny_map(seed: int) -> torch.Tensor:
    env = random_map(seed)
    env[2, 5] = 400.0  # a texel carrying most of the light: the one the direct light is drawn for
    return env


def test_bright_texels_alone_drawn_still_give_the_path_tracers_images(problem):
    """With the direct light drawn only for the bright texels and the BSDF's samples taking the others, the images
    under other maps are still the path tracer's (its noise aside): a glossy object's cheaper recording."""
    view, glossy = problem.train_ids[0], MaterialTextures.constant(SIZE, 0.6, 0.08, 1.0)
    t = record_view(problem, view, glossy, guide_map(sunny_map(0)), TransportConfig(spp=1024), seed=3,
                    every_texel=False)
    mask = problem.masks[view].numpy()
    for seed, env in ((5, sunny_map(5)), (6, random_map(6, 2.0))):
        albedo = random_albedo(seed)
        mats = MaterialTextures(albedo, glossy.roughness, glossy.metallic)
        cached = t.image(env.numpy(), albedo.numpy())[mask]
        reference = render_mean(problem, env, mats, view)[mask]
        independent = render_mean(problem, env, mats, view, seeds=[11], spp=256)[mask]
        noise = np.sqrt(np.mean((independent - reference) ** 2))
        assert abs(cached.mean() - reference.mean()) < 0.02 * reference.mean()
        assert np.sqrt(np.mean((cached - reference) ** 2)) < 1.5 * noise


@pytest.fixture(scope="module")
def transport(problem):
    return record_transport(problem, materials(), random_map(2), TransportConfig(spp=16), seed=4)


def test_the_halves_product_is_the_data_term_without_the_recordings_noise(problem, transport):
    env, albedo = random_map(7), random_albedo(7)
    reference = []
    for v in problem.train_ids:  # the residual of a render far less noisy than the recording
        mask = problem.masks[v].numpy()
        reference.append((render_mean(problem, env, MaterialTextures(albedo, materials().roughness,
                                                                     materials().metallic), v, spp=512)
                          - problem.images[v].numpy())[mask])
    truth = float(np.square(np.concatenate(reference)).sum())
    first, second = transport.halves(env, albedo) - transport.observed.float()
    one_half = float(first.square().sum())  # one recording's squares: its noise adds to them
    unbiased = float(transport.sum_squares(env, albedo))
    assert one_half - truth > 0.02 * truth  # measured: 4 % over
    assert abs(unbiased - truth) < 0.25 * (one_half - truth)  # measured: 0.5 % off
    assert transport.pixels == transport.foreground == sum(int(problem.masks[v].sum()) for v in problem.train_ids)


def test_image_equations_are_the_fit_loss_and_its_gradient(transport):
    albedo, env = random_albedo(10), random_map(10).double()
    equations = transport.image_equations(albedo)
    fit = float(transport.fit_loss(env, albedo))
    assert float(equations.sum_squares(env)) == pytest.approx(fit, rel=1e-4)
    flat = env.reshape(-1, 3).T
    leaf = env.clone().requires_grad_(True)
    transport.fit_loss(leaf, albedo).backward()
    np.testing.assert_allclose(leaf.grad.reshape(-1, 3).T.numpy(),
                               (2 * (equations.apply(flat) - equations.rhs)).numpy(), rtol=1e-3,
                               atol=1e-4 * float(leaf.grad.abs().max()))
    units = torch.eye(flat.shape[1], dtype=torch.float64)[:5]  # the diagonal: e_i^T G e_i
    for i, unit in enumerate(units):
        assert float(equations.apply(unit.expand(3, -1))[0, i]) == pytest.approx(
            float(equations.diagonal()[0, i]), rel=1e-4)


def test_the_data_terms_gradient_in_the_albedo_is_its_finite_difference(transport):
    env, albedo = random_map(9), random_albedo(9)
    leaf = albedo.clone().requires_grad_(True)  # its gradient through the lookup, against finite differences
    transport.sum_squares(env, leaf).backward()
    bump = torch.zeros_like(albedo)
    bump[3, 4, 1] = 1e-2
    fd = (float(transport.sum_squares(env, albedo + bump)) - float(transport.sum_squares(env, albedo - bump))) / 2e-2
    assert fd == pytest.approx(float(leaf.grad[3, 4, 1]), rel=1e-2, abs=1e-6)


def test_gradient_of_the_transport_is_drjits(problem, recorded):
    """d/dL of sum(r * image) is T^T r: from the recording against Dr.Jit's backward through Mitsuba."""
    view, t = recorded
    env, albedo = random_map(7), random_albedo(7)
    r = torch.rand(*problem.masks[view].shape, 3, generator=torch.Generator().manual_seed(9))
    r = (r * problem.masks[view][..., None]).reshape(-1, 3).numpy()[t.pixels]
    rows, index, weight = t.lookup
    seen = np.zeros((len(t.pixels), 3))
    np.add.at(seen, rows, weight[:, None] * albedo.numpy().reshape(-1, 3)[index])
    slope, offset = t.matrix[0].mean(0), t.matrix[1].mean(0)  # (3, pixels, texels), the halves' mean
    ours = np.einsum("cpn,pc->nc", seen.T[:, :, None] * slope + offset, r)
    grads = []
    mats = MaterialTextures(albedo, materials().roughness, materials().metallic)
    pixels = torch.from_numpy(t.pixels)
    for seed in range(4):
        leaf = env.clone().requires_grad_(True)
        image = problem.render(leaf, mats, view, seed=100 + seed, spp=256).reshape(-1, 3)[pixels]
        (image * torch.from_numpy(r).float()).sum().backward()
        grads.append(leaf.grad.reshape(-1, 3).numpy())
    drjit, spread = np.mean(grads, axis=0), np.std(grads, axis=0) / 2
    seen_texels = drjit > 0.05 * drjit.max()
    assert np.corrcoef(ours[seen_texels], drjit[seen_texels])[0, 1] > 0.95
    assert abs(ours.sum() - drjit.sum()) < 0.03 * drjit.sum() + 3 * spread.sum() / np.sqrt(drjit.size)


def test_pixels_beyond_the_limit_are_an_even_subset_and_weigh_for_the_rest(problem):
    rng = np.random.default_rng(0)
    everything = transport_pixels(problem, 10 ** 6, rng)
    total = sum(len(p) for p in everything.values())
    chosen = transport_pixels(problem, total // 4, rng)
    for v in problem.train_ids:
        assert set(chosen[v]) <= set(everything[v])
        assert len(chosen[v]) == pytest.approx(len(everything[v]) / 4, abs=1)
    with pytest.raises(ValueError, match="spp: must be a multiple of 2"):
        TransportConfig(spp=3)


def test_the_direct_light_takes_a_quarter_of_the_paths_split_between_the_halves():
    assert [TransportConfig(spp=s).direct_spp for s in (2, 8, 16, 20, 128)] == [2, 2, 4, 4, 32]
