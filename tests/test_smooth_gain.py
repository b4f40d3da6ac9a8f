"""The smooth-gain refinement of a sampled map (dpi.solve.smooth_gain)."""

import numpy as np
import pytest
import torch

from dpi.light.envmap import texel_directions, texel_solid_angles
from dpi.solve.dps import DPSConfig
from dpi.solve.smooth_gain import SmoothGain, sh_basis


def test_sh_basis_is_orthonormal_over_the_sphere():
    basis = sh_basis(texel_directions(128), 2)
    weighted = basis * texel_solid_angles(128)[..., None]
    gram = np.einsum("hwi,hwj->ij", weighted, basis)
    np.testing.assert_allclose(gram, np.eye(9), atol=2e-3)


def test_sh_basis_rejects_orders_above_two():
    with pytest.raises(ValueError, match="order"):
        sh_basis(texel_directions(4), 3)


def test_smooth_gain_starts_at_the_map_and_recovers_a_low_order_gain():
    torch.manual_seed(0)
    base = torch.randn(16, 32, 3)
    model = SmoothGain(base, order=1)
    torch.testing.assert_close(model(), base)
    truth = torch.tensor([[0.3, -0.2, 0.1], [0.5, 0.0, -0.4], [-0.1, 0.2, 0.0], [0.0, 0.3, 0.2]])
    target = base + model.basis @ truth
    optimizer = torch.optim.Adam(model.parameters(), lr=0.05)
    for _ in range(400):
        optimizer.zero_grad()
        (model() - target).square().mean().backward()
        optimizer.step()
    torch.testing.assert_close(model.coefficients.detach(), truth, atol=1e-3, rtol=0)
    assert [name for name, _ in model.named_parameters()] == ["coefficients"]


def test_polish_moves_every_texel_at_its_share_of_the_rate():
    torch.manual_seed(1)
    base = torch.randn(8, 16, 3)
    model = SmoothGain(base, order=0, polish=0.1)
    torch.testing.assert_close(model(), base)
    target = base + torch.randn_like(base)
    optimizer = torch.optim.Adam([model.texels], lr=0.05)
    optimizer.zero_grad()
    (model() - target).square().sum().backward()
    optimizer.step()
    # Adam's first step is the rate times the gradient's sign: 0.05 on the texel parameter, 0.005 on the map
    step = (model() - base).detach()
    torch.testing.assert_close(step.abs(), torch.full_like(base, 0.005), atol=1e-6, rtol=0)
    assert bool(((target - base) * step > 0).all())


def test_a_coarse_polish_fits_the_views_broad_part_and_keeps_the_maps_detail():
    """On a grid of 4 rows under a 16-row map: a target that is the map plus a smooth field is reached, and the
    map's own texel-scale detail (what a 4-row grid cannot hold) is left as it was."""
    torch.manual_seed(2)
    base = torch.randn(16, 32, 3)
    model = SmoothGain(base, order=0, polish=1.0, polish_height=4)
    assert tuple(model.texels.shape) == (4, 8, 3)
    coarse = torch.randn(1, 3, 4, 8)
    field = torch.nn.functional.interpolate(coarse, size=(16, 32), mode="bilinear", align_corners=False)[0]
    target = base + field.permute(1, 2, 0)
    optimizer = torch.optim.Adam(model.parameters(), lr=0.05)
    for _ in range(600):
        optimizer.zero_grad()
        (model() - target).square().mean().backward()
        optimizer.step()
    torch.testing.assert_close(model().detach(), target, atol=2e-3, rtol=0)
    detail = base - torch.nn.functional.avg_pool2d(base.permute(2, 0, 1)[None], 4).repeat_interleave(4, -1) \
        .repeat_interleave(4, -2)[0].permute(1, 2, 0)
    change = model().detach() - base
    assert float((change * detail).sum() / detail.square().sum()) == pytest.approx(0, abs=0.02)


def test_refine_settings_are_checked():
    assert DPSConfig.from_dict({"refine": {"lr_texels": 0.01}}).refine.lr_texels == 0.01
    with pytest.raises(ValueError, match="refine.lr_gain: must be > 0"):
        DPSConfig.from_dict({"refine": {"lr_gain": 0}})
