"""notebook/scripts/balance_views.py's measures: a map's coarse balance moved exactly, an albedo's broad field known."""

import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "notebook" / "scripts"))
from balance_views import broad_field, coarse_log, with_balance  # noqa: E402


def test_with_balance_sets_the_coarse_balance_and_keeps_the_detail():
    rng = np.random.default_rng(0)
    env = torch.from_numpy(rng.uniform(0.5, 2.0, (16, 32, 3))).float()
    target = torch.from_numpy(rng.normal(0.0, 1.0, (1, 3, 2, 4))).float()
    moved = with_balance(env, target)
    difference = coarse_log(moved) - target
    assert torch.allclose(difference, difference.mean(dim=(2, 3), keepdim=True).expand_as(difference), atol=1e-5)
    ratio = moved / env  # one factor per coarse cell: the detail within a cell is untouched
    assert torch.allclose(ratio[:8, :8], ratio[0, 0].expand(8, 8, 3), rtol=1e-5)


def test_broad_field_of_a_known_slope():
    normals = np.random.default_rng(1).normal(size=(32, 32, 3))
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    albedo = np.repeat(0.4 * np.exp(0.3 * normals[..., 2:3]), 3, axis=-1)
    mask = np.ones((32, 32), bool)
    assert abs(broad_field(albedo, normals, mask) - 0.3 / np.sqrt(3)) < 1e-3
    assert broad_field(np.full((32, 32, 3), 0.4), normals, mask) < 1e-6
