"""The lobe width a sample starts from: the non-negative map solved exactly, and the level whose views it explains
best chosen (dpi.solve.dps.lobe_choice)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.optimize import nnls

from dpi.capture import load_capture
from dpi.render.renderer import RenderConfig
from dpi.solve.dps.lobe_choice import LOBE_FACTORS, favoured_level, nonnegative_quadratic
from dpi.solve.materials import MaterialTextures
from dpi.solve.problem import InverseProblem, ProblemConfig
from dpi.solve.transport import TransportConfig, record_transport

HEIGHT, SIZE = 8, 8


def test_nonnegative_quadratic_is_nnls_where_the_free_solution_goes_negative():
    rng = np.random.default_rng(3)
    matrix = rng.normal(size=(200, 12))
    target = matrix @ np.concatenate([rng.uniform(0.5, 1.0, 6), -rng.uniform(0.5, 1.0, 6)])
    x = nonnegative_quadratic(matrix.T @ matrix, matrix.T @ target)
    assert (x >= 0).all() and (x[6:] < 1e-6).any()
    np.testing.assert_allclose(x, nnls(matrix, target)[0], atol=1e-6)


@pytest.fixture(scope="module")
def transport(tiny_capture):
    problem = InverseProblem(load_capture(tiny_capture), ProblemConfig(env_height=HEIGHT, texture_size=SIZE),
                             RenderConfig(spp=16, threads=2))
    materials = MaterialTextures.constant(SIZE, 0.6, 0.35, 0.0)
    env = torch.exp(torch.randn(HEIGHT, 2 * HEIGHT, 3, generator=torch.Generator().manual_seed(1)))
    return record_transport(problem, materials, env, TransportConfig(spp=32), seed=2, levels=LOBE_FACTORS)


@pytest.mark.parametrize("truth", [0, 1, 4])
def test_the_level_the_views_were_made_at_is_favoured(transport, truth):
    albedo = torch.full((SIZE, SIZE, 3), 0.6)
    env = torch.exp(torch.randn(HEIGHT, 2 * HEIGHT, 3, generator=torch.Generator().manual_seed(5)))
    with torch.no_grad():
        views = transport.image(env, albedo, truth)
    made = type(transport)(transport.matrix, transport.lookup, views, transport.height, transport.roughness,
                           transport.materials, transport.foreground, transport.seconds)
    level, shares = favoured_level(made, albedo)
    assert level == truth and len(shares) == 1 + len(LOBE_FACTORS)


def test_at_level_keeps_that_levels_transport_and_roughness(transport):
    kept = transport.at_level(3)
    albedo, env = torch.full((SIZE, SIZE, 3), 0.4), torch.ones(HEIGHT, 2 * HEIGHT, 3)
    torch.testing.assert_close(kept.image(env, albedo), transport.image(env, albedo, 3))
    torch.testing.assert_close(kept.materials.roughness, transport.roughness[3])
    assert torch.allclose(transport.roughness[3].square(), LOBE_FACTORS[2] * transport.roughness[0].square())
