"""Network layers over equirectangular maps that follow the sphere: a convolution and a 2x upsampling that pad
circularly in azimuth and across the poles (dpi.light.envmap.pad_equirect), so what they make has no seam, and the
resampling of a network's map to the problem's size. The networks of `dip`, `gan` and `reni` use them."""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

from dpi.light.envmap import pad_equirect


class EquirectConv(nn.Module):
    """A k x k convolution (optionally strided) that pads across the sphere instead of with zeros."""

    def __init__(self, c_in: int, c_out: int, kernel: int, stride: int = 1):
        super().__init__()
        self.pad = kernel // 2
        self.conv = nn.Conv2d(c_in, c_out, kernel, stride)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(B, c_in, h, w) -> (B, c_out, h / stride, w / stride)."""
        return self.conv(pad_equirect(x, self.pad))


def upsample(x: torch.Tensor) -> torch.Tensor:
    """Bilinear 2x upsampling whose interpolation wraps in azimuth and across the poles."""
    padded = F.interpolate(pad_equirect(x, 1), scale_factor=2, mode="bilinear", align_corners=False)
    return padded[..., 2:-2, 2:-2]


def resample_rows(x: torch.Tensor, height: int) -> torch.Tensor:
    """A (..., h, 2h) map at `height` rows: doubled across the sphere or area-halved until it has them (h and `height`
    a power of two apart)."""
    while x.shape[-2] < height:
        x = upsample(x)
    while x.shape[-2] > height:
        x = F.avg_pool2d(x, 2)
    return x
