"""The realism distance: a sliced Wasserstein distance between patch clouds of log radiance (known answers)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from dpi.evaluation.realism import RealismConfig, realism_distance, sliced_wasserstein


def test_sliced_wasserstein_of_a_shifted_cloud_is_the_shift_over_root_d():
    """For b = a + s, every projection on a unit direction u moves by s.u, and E[(s.u)^2] = |s|^2 / D."""
    a = torch.randn(4000, 6, generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    shift = torch.tensor([1.0, -2.0, 0.5, 0.0, 1.5, -1.0], dtype=torch.float64)
    cfg = RealismConfig(projections=4000)
    assert sliced_wasserstein(a, a + shift, cfg) == pytest.approx(float(shift.norm()) / 6 ** 0.5, rel=0.05)
    assert sliced_wasserstein(a, a, cfg) == 0.0


def smooth_map(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    rows = np.linspace(2.0, 0.2, 32)[:, None, None]
    return (rows * (0.5 + rng.random((32, 64, 3)))).astype(np.float32)


def test_the_distance_ignores_exposure_and_orders_sets_by_likeness():
    real = [smooth_map(i) for i in range(4)]
    assert realism_distance([8.0 * m for m in real], real) == pytest.approx(0.0, abs=1e-9)
    near = [smooth_map(10 + i) for i in range(4)]  # same kind of map, other draws
    flipped = [m[::-1].copy() for m in near]  # bright ground, dark sky: the patches' elevations disagree
    flat = [np.full((32, 64, 3), 1.0, np.float32) for _ in range(4)]
    d_near, d_flipped, d_flat = (realism_distance(s, real) for s in (near, flipped, flat))
    assert d_near < d_flipped and d_near < d_flat
    assert realism_distance(near, real) == pytest.approx(realism_distance(real, near), rel=1e-9)


def test_a_samples_realism_is_its_distance_to_the_reference_folder(tmp_path):
    from dpi.evaluation.realism import env_realism
    from dpi.io.exr import write_exr

    refs = [smooth_map(i) for i in range(3)]
    for i, m in enumerate(refs):
        write_exr(tmp_path / f"ref_{i}.exr", m)
    sample = smooth_map(9)
    assert env_realism(sample, tmp_path) == pytest.approx(realism_distance([sample], refs), rel=1e-6)
    assert env_realism(sample, None).startswith("missing: no evaluate.reference_panoramas")

