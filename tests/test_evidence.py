"""The readings' evidence (dpi.solve.evidence): known answers for the Laplace evidence's parts, and the posterior
probability from a log Bayes factor."""

import math

import pytest
import torch

from dpi.solve.evidence import channel_log_evidence, glossy_probability


def equations(u: torch.Tensor, pinned: torch.Tensor, residual: float) -> tuple[torch.Tensor, torch.Tensor, float]:
    """Normal equations with G = diag(pinned) whose residual at the map u is `residual`: b = G u, y^T y =
    u^T G u + residual."""
    gram = torch.diag(pinned.double())
    return gram, gram @ u, float(u @ gram @ u) + residual


def test_views_that_see_nothing_cost_no_occam_factor():
    u = torch.tensor([1.0, 2.0, 4.0], dtype=torch.float64)
    gram, rhs, squares = equations(u, torch.zeros(3), residual=0.5)
    expected = -10 / 2 * math.log(2 * math.pi * 0.5 / 10) - 10 / 2 - 3 / 2
    assert channel_log_evidence(gram, rhs, squares, 10, u) == pytest.approx(expected)


def test_a_map_the_views_pin_more_pays_for_each_direction_they_pin():
    u = torch.tensor([1.0, 2.0, 4.0], dtype=torch.float64)
    spread, noise = float(torch.log(u).var()), 0.5 / 10
    loose, tight = torch.tensor([0.1, 0.0, 0.0]), torch.tensor([0.1, 5.0, 3.0])
    evidence = {name: channel_log_evidence(*equations(u, pinned, residual=0.5), 10, u)
                for name, pinned in (("loose", loose), ("tight", tight))}
    occam = {name: sum(math.log1p(spread * float(p) * float(x) ** 2 / noise) for p, x in zip(pinned, u))
             for name, pinned in (("loose", loose), ("tight", tight))}
    assert evidence["loose"] - evidence["tight"] == pytest.approx((occam["tight"] - occam["loose"]) / 2)
    assert evidence["tight"] < evidence["loose"]  # the same fit with more of the map pinned: less evidence


def test_a_better_fit_under_the_same_freedom_has_more_evidence():
    u = torch.tensor([1.0, 2.0, 4.0], dtype=torch.float64)
    pinned = torch.tensor([1.0, 1.0, 1.0])
    better, worse = (channel_log_evidence(*equations(u, pinned, residual=r), 100, u) for r in (0.5, 1.0))
    assert better > worse


@pytest.mark.parametrize("factor", [-1000.0, -3.0, 0.0, 2.0, 800.0])
def test_the_glossy_probability_is_the_logistic_of_the_factor(factor):
    p = glossy_probability(factor)
    assert 0.0 <= p <= 1.0 and p + glossy_probability(-factor) == pytest.approx(1.0)
    assert p == pytest.approx(1 / (1 + math.exp(-factor)) if abs(factor) < 700 else float(factor > 0))
