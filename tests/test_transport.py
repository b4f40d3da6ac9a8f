"""The recorded light transport: Mitsuba's envmap lookup exactly, T L against the path tracer under other
maps, its gradient against Dr.Jit's, the normal equations against the views, and a refresh after the
materials move."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from dpi.capture import load_capture
from dpi.materials import MaterialTextures
from dpi.render import RenderSettings
from dpi.solve.problem import InverseProblem, ProblemSettings
from dpi.solve.transport import guide_map, record_transport, record_view, texel_weights

HEIGHT = 8


@pytest.fixture(scope="module")
def problem(tiny_capture):
    return InverseProblem(load_capture(tiny_capture), ProblemSettings(env_height=HEIGHT, texture_size=8),
                          RenderSettings(spp=16, threads=2))


def random_map(seed: int, spread: float = 1.0) -> torch.Tensor:
    return torch.exp(spread * torch.randn(HEIGHT, 2 * HEIGHT, 3, generator=torch.Generator().manual_seed(seed)))


def materials(albedo: float = 0.6) -> MaterialTextures:
    mats = MaterialTextures.constant(8, albedo, 0.35, 0.2)
    mats.albedo = mats.albedo * torch.linspace(0.5, 1.0, 8)[:, None, None]
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


def render_mean(problem, env, mats, view, seeds=range(3), spp=256) -> np.ndarray:
    with torch.no_grad():
        return np.mean([problem.render(env, mats, view, seed=s, spp=spp).numpy() for s in seeds], axis=0)


def test_transport_renders_other_maps_like_the_path_tracer(problem):
    view, mats = problem.train_ids[0], materials()
    t = record_view(problem, view, mats, guide_map(random_map(0)), spp=256, seed=3, direct_spp=256)
    mask = problem.masks[view].numpy()
    for seed, spread in ((5, 1.0), (6, 2.0)):  # maps the recording's guide never saw, up to e^4 dynamic range
        env = random_map(seed, spread)
        cached, reference = t.image(env.numpy())[mask], render_mean(problem, env, mats, view)[mask]
        independent = render_mean(problem, env, mats, view, seeds=[11], spp=256)[mask]
        noise = np.sqrt(np.mean((independent - reference) ** 2))
        assert abs(cached.mean() - reference.mean()) < 0.02 * reference.mean()
        assert np.sqrt(np.mean((cached - reference) ** 2)) < 1.5 * noise  # within the path tracer's own noise


def test_normal_equations_give_the_views_loss_and_its_gradient(problem):
    mats, env = materials(), random_map(2)
    transport = record_transport(problem, mats, env, spp=64, seed=4)
    views = [record_view(problem, v, mats, guide_map(env), spp=64, seed=4 * 1009 + j)
             for j, v in enumerate(problem.train_ids)]
    residuals = [t.image(env.numpy()) - problem.images[v].numpy() for t, v in zip(views, problem.train_ids)]
    direct = sum(float(np.square(r[problem.masks[v].numpy()]).sum()) for r, v in zip(residuals, problem.train_ids))
    noise = float((transport.column_variance * env.reshape(-1, 3).T.double().square()).sum())
    assert 0 < noise < 0.1 * direct  # T's own noise, which the normal equations leave out
    assert direct - noise - 1e-6 <= float(transport.sum_squares(env)) < direct  # (G is kept convex: not below)
    assert float(torch.linalg.eigvalsh(transport.gram).min()) > -1e-9 * float(transport.gram.abs().max())
    assert transport.pixels == sum(int(problem.masks[v].sum()) for v in problem.train_ids)
    leaf = env.clone().double().requires_grad_(True)
    transport.sum_squares(leaf).backward()
    flat = leaf.detach().reshape(-1, 3).T
    analytic = 2 * (torch.einsum("cij,cj->ci", transport.gram, flat) - transport.rhs)
    torch.testing.assert_close(leaf.grad.reshape(-1, 3).T, analytic)
    bump = torch.zeros_like(env)
    bump[3, 5, 1] = 1e-3
    fd = (float(transport.sum_squares(env.double() + bump)) - float(transport.sum_squares(env.double() - bump))) / 2e-3
    assert fd == pytest.approx(float(leaf.grad[3, 5, 1]), rel=1e-4)


def test_gradient_of_the_transport_is_drjits(problem):
    """d/dL of sum(r * image) is T^T r: from the recording against Dr.Jit's backward through Mitsuba."""
    view, mats = problem.train_ids[1], materials()
    env = random_map(7)
    t = record_view(problem, view, mats, guide_map(env), spp=512, seed=8, direct_spp=256)
    r = torch.rand(*problem.masks[view].shape, 3, generator=torch.Generator().manual_seed(9))
    r = r * problem.masks[view][..., None]
    ours = np.einsum("cpn,pc->nc", t.matrix, r.reshape(-1, 3).numpy()[t.pixels])
    grads = []
    for seed in range(4):
        leaf = env.clone().requires_grad_(True)
        (problem.render(leaf, mats, view, seed=100 + seed, spp=256) * r).sum().backward()
        grads.append(leaf.grad.reshape(-1, 3).numpy())
    drjit, spread = np.mean(grads, axis=0), np.std(grads, axis=0) / 2
    seen = drjit > 0.05 * drjit.max()
    assert np.corrcoef(ours[seen], drjit[seen])[0, 1] > 0.95
    assert abs(ours.sum() - drjit.sum()) < 0.03 * drjit.sum() + 3 * spread.sum() / np.sqrt(drjit.size)


def test_a_refresh_after_the_materials_move_restores_agreement(problem):
    view, env = problem.train_ids[0], random_map(3)
    before, after = materials(0.6), materials(0.6)
    after.albedo = after.albedo * torch.tensor([0.4, 1.0, 1.6]).clamp(max=1 / after.albedo.max())
    stale = record_transport(problem, before, env, spp=64, seed=5, views=[view])
    mask = problem.masks[view].numpy()
    reference = render_mean(problem, env, after, view)[mask]
    assert not stale.stale(before, 0.02) and stale.stale(after, 0.02)
    old = record_view(problem, view, before, guide_map(env), spp=128, seed=6, direct_spp=64).image(env.numpy())[mask]
    new = record_view(problem, view, after, guide_map(env), spp=128, seed=6, direct_spp=64).image(env.numpy())[mask]
    error = lambda image: np.sqrt(np.mean((image - reference) ** 2)) / reference.mean()  # noqa: E731
    assert error(new) < 0.15 < error(old)  # measured: 0.09 (path-tracing noise) against 0.47
