"""The parametric sun of dps: a splat that keeps its energy and direction, extraction that finds a sun in
a map, the share prior, and a sampler run that fits the sun where the data hold one."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from dpi.envmap import direction_to_uv, texel_directions
from dpi.solve.sun import extract_sun, map_energy, share_penalty, sun_direction_of, sun_env, wrap_uv_


@pytest.mark.parametrize("uv", [(0.3, 0.27), (0.995, 0.5), (0.0, 0.01), (0.6, 0.99)])
def test_splat_carries_its_irradiance_anywhere_on_the_map(uv):
    irradiance = torch.tensor([1.0, 2.0, 3.0])
    env = sun_env(torch.tensor(uv), irradiance, 8)
    torch.testing.assert_close(map_energy(env), irradiance)
    assert int((env.sum(-1) > 0).sum()) <= 4


@pytest.mark.parametrize("uv", [(0.3, 0.27), (0.995, 0.5), (0.6, 0.99)])
def test_a_sun_splatted_coarser_covers_the_coarse_texels_with_its_energy(uv):
    irradiance = torch.tensor([1.0, 2.0, 3.0])
    fine = sun_env(torch.tensor(uv), irradiance, 16, splat_height=4)
    torch.testing.assert_close(map_energy(fine), irradiance)
    coarse = sun_env(torch.tensor(uv), irradiance, 4)
    lit = torch.nn.functional.interpolate((coarse.sum(-1) > 0).float()[None, None], size=(16, 32))[0, 0] > 0
    assert torch.equal(fine.sum(-1) > 0, lit)
    torch.testing.assert_close(sun_env(torch.tensor(uv), irradiance, 4, splat_height=16), coarse)


def test_splat_gradient_in_the_sun_position_matches_finite_differences():
    weights = torch.rand(8, 16, generator=torch.Generator().manual_seed(0))
    irradiance = torch.tensor([1.0, 1.0, 1.0], dtype=torch.float64)

    def f(uv: torch.Tensor) -> torch.Tensor:
        return (weights.double()[..., None] * sun_env(uv, irradiance, 8)).sum()

    uv = torch.tensor([0.41, 0.37], dtype=torch.float64, requires_grad=True)
    f(uv).backward()
    h = 1e-6
    for k in range(2):
        step = torch.zeros(2, dtype=torch.float64)
        step[k] = h
        numeric = (f(uv.detach() + step) - f(uv.detach() - step)) / (2 * h)
        assert float(uv.grad[k]) == pytest.approx(float(numeric), rel=1e-5)


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
