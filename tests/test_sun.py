"""The parametric sun of dps: a drawn disc that keeps its energy and direction, extraction that finds a sun in
a map, the share prior, and a sampler run that fits the sun where the data hold one."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from dpi.light.envmap import direction_to_uv, texel_directions, texel_solid_angles
from dpi.light.sunlight import AUREOLE_SHARE, find_spots, merge_spots_into_sun
from dpi.solve.sun_model import extract_sun, map_energy, share_penalty, sun_direction_of, sun_env, wrap_uv_


@pytest.mark.parametrize("height", [8, 32, 128])
@pytest.mark.parametrize("uv", [(0.3, 0.27), (0.995, 0.5), (0.0, 0.01), (0.6, 0.99)])
def test_a_drawn_sun_carries_its_irradiance_anywhere_on_any_map(uv, height):
    irradiance = torch.tensor([1.0, 2.0, 3.0], dtype=torch.float64)
    env = sun_env(torch.tensor(uv, dtype=torch.float64), irradiance, height)
    torch.testing.assert_close(map_energy(env), irradiance)


@pytest.mark.parametrize("uv", [(0.3, 0.27), (0.713, 0.45), (0.999, 0.6)])
def test_at_128_rows_the_sun_is_a_disc_of_a_few_texels_with_a_faint_aureole(uv):
    env = sun_env(torch.tensor(uv, dtype=torch.float64), torch.ones(3, dtype=torch.float64), 128).numpy()
    omega = texel_solid_angles(128)
    energy = np.sort((env[..., 0] * omega).ravel())[::-1]
    assert energy[:4].sum() > 0.85  # the disc: one texel or a few
    assert energy[:4].sum() < 1 - 0.5 * AUREOLE_SHARE  # and the aureole around it
    spots = find_spots(torch.as_tensor(env) + 1 / (4 * math.pi))  # over a sky as bright as the sun, as a clear day's
    assert len(spots) == 1
    angle = math.degrees(math.acos(min(1.0, float(spots[0].direction @ torch.as_tensor(sun_direction_of(torch.tensor(uv)))))))
    assert angle < 0.7  # half a texel


def test_sun_gradient_in_its_position_matches_finite_differences():
    weights = torch.rand(16, 32, generator=torch.Generator().manual_seed(0)).double()
    irradiance = torch.tensor([1.0, 1.0, 1.0], dtype=torch.float64)

    def f(uv: torch.Tensor) -> torch.Tensor:
        return (weights[..., None] * sun_env(uv, irradiance, 16)).sum()

    uv = torch.tensor([0.41, 0.37], dtype=torch.float64, requires_grad=True)
    f(uv).backward()
    assert float(uv.grad.abs().min()) > 0
    h = 1e-6
    for k in range(2):
        step = torch.zeros(2, dtype=torch.float64)
        step[k] = h
        numeric = (f(uv.detach() + step) - f(uv.detach() - step)) / (2 * h)
        assert float(uv.grad[k]) == pytest.approx(float(numeric), rel=1e-4)


def test_a_second_sun_in_the_sky_is_merged_into_the_fitted_one():
    height = 64
    dirs = torch.as_tensor(texel_directions(height))
    sky = (1.0 + 0.5 * dirs[..., 1:2].clamp_min(0)) * torch.tensor([0.6, 0.8, 1.0], dtype=torch.float64)
    stray = sun_env(torch.tensor([0.8, 0.3], dtype=torch.float64), torch.tensor([1.0, 1.0, 0.8], dtype=torch.float64), 16)
    stray = torch.nn.functional.interpolate(stray.permute(2, 0, 1)[None], size=(height, 2 * height),
                                            mode="bilinear", align_corners=False)[0].permute(1, 2, 0)
    assert len(find_spots(sky)) == 0 and len(find_spots(sky + stray)) == 1  # a blurred second sun, ~10x its sky
    uv = torch.tensor([0.2, 0.25], dtype=torch.float64)
    fitted = torch.tensor([5.0, 4.8, 4.0], dtype=torch.float64)
    merged_sky, irradiance, count = merge_spots_into_sun(sky + stray, fitted, 64)
    assert count == 1
    env = merged_sky + sun_env(uv, irradiance, height)
    torch.testing.assert_close(map_energy(env), map_energy(sky + stray) + fitted)
    spots = find_spots(env)
    assert len(spots) == 1
    assert float(spots[0].direction @ torch.as_tensor(sun_direction_of(uv))) > math.cos(math.radians(1))


def test_position_round_trips_through_the_world_direction():
    uv = torch.tensor([0.137, 0.62])
    np.testing.assert_allclose(direction_to_uv(sun_direction_of(uv)), uv.numpy(), atol=1e-6)
    wrapped = torch.tensor([1.25, 1.3])
    wrap_uv_(wrapped)
    torch.testing.assert_close(wrapped, torch.tensor([0.25, 1.0]))


def test_extraction_recovers_a_sun_over_a_smooth_sky():
    height = 16
    dirs = torch.as_tensor(texel_directions(height), dtype=torch.float32)
    sky = (1.0 + 0.2 * dirs[..., 1:2].clamp_min(0)) * torch.tensor([0.6, 0.8, 1.0])
    uv, irradiance = torch.tensor([0.3, 0.3]), torch.tensor([2.0, 1.8, 1.5])
    extraction = extract_sun(sky + sun_env(uv, irradiance, height))
    torch.testing.assert_close(extraction.irradiance, irradiance, rtol=0.05, atol=0.0)
    angle = math.degrees(math.acos(float(np.dot(sun_direction_of(extraction.uv), sun_direction_of(uv)))))
    assert angle < 2.0
    assert float((extraction.sky - sky).abs().max()) < 0.1 * float(sky.max())
    total = float((map_energy(sky) + irradiance).mean())
    assert extraction.share == pytest.approx(float(irradiance.mean()) / total, rel=0.1)


def test_share_penalty_vanishes_at_its_target_and_grows_away_from_it():
    env = torch.ones(8, 16, 3)
    sky_energy = float(map_energy(env)[0])
    sun = torch.full((3,), sky_energy)  # the sun carries half of sky + sun
    full = env + sun_env(torch.tensor([0.5, 0.5]), sun, 8)
    assert float(share_penalty(sun, full, 0.5)) == pytest.approx(0.0, abs=1e-8)
    assert float(share_penalty(sun, full, 0.8)) > float(share_penalty(sun, full, 0.6)) > 0


class RadiusProblem:
    """A stand-in whose training loss is (radius - best)^2 plus a seed's noise of std `noise` (the env carries r)."""

    def __init__(self, best: float, noise: float):
        self.best, self.noise, self.train_ids = best, noise, list(range(3))

    def data_loss(self, env, materials, views, seed):
        jitter = np.random.default_rng(seed).normal(0.0, self.noise)
        return (float(env[0, 0, 0]) - self.best) ** 2 + jitter


def test_the_written_suns_size_is_the_one_the_views_favour_else_the_suns_own():
    from dpi.light.sunlight import SUN_RADIUS_DEG
    from dpi.solve.dps.sun_size import sun_radii, views_sun_radius

    def env_with_sun(radius):
        return torch.full((2, 4, 3), radius)

    radii = sun_radii(32)  # from the sun's own, doubling up to a texel of a 32-row map
    assert radii[0] == SUN_RADIUS_DEG and radii[-1] <= 180 / 32 < 2 * radii[-1] and len(radii) == 5
    radius, losses = views_sun_radius(RadiusProblem(radii[2], 1e-6), env_with_sun, None, seed=0, prior_rows=32)
    assert radius == radii[2] and set(losses) == {f"{r:g}" for r in radii}
    # views that cannot tell the sizes apart (differences far inside their noise) keep the sun's own
    radius, _ = views_sun_radius(RadiusProblem(radii[2], 1e3), env_with_sun, None, seed=0, prior_rows=32)
    assert radius == SUN_RADIUS_DEG


@pytest.mark.parametrize("radius", [0.2665, 2.0, 8.0])
def test_a_sun_of_any_radius_keeps_its_energy(radius):
    uv, irradiance = torch.tensor([0.3, 0.35]), torch.tensor([3.0, 2.0, 1.0])
    torch.testing.assert_close(map_energy(sun_env(uv, irradiance, 64, radius)).float(), irradiance, rtol=1e-4,
                               atol=1e-5)


def test_a_larger_sun_spreads_its_energy_over_more_texels():
    uv, irradiance = torch.tensor([0.3, 0.35]), torch.tensor([3.0, 2.0, 1.0])
    own, wide = (sun_env(uv, irradiance, 64, r)[..., 0] for r in (0.2665, 8.0))
    assert float(wide.max()) < 0.1 * float(own.max())
    assert int((wide > 0.5 * wide.max()).sum()) > 10 * int((own > 0.5 * own.max()).sum())
