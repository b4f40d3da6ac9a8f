"""The invertible tone curve between linear HDR radiance and the prior's [-1, 1] image space.

x = 2 f(L / scale) - 1 with f(L) = a L^(1/gamma); back: L = scale ((x + 1) / 2 / a)^gamma.
Paper values: outdoor a=0.5, gamma=2.4; indoor a=0.9, gamma=6.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch


@dataclass(frozen=True)
class ToneCurve:
    """Parameters of f(L) = a L^(1/gamma) and the per-scene radiance scale."""

    a: float
    gamma: float
    scale: float = 1.0

    def to_prior(self, radiance: torch.Tensor) -> torch.Tensor:
        """Linear HDR radiance (>= 0) -> prior space x in [-1, 1] (values above 1 are clamped)."""
        f = self.a * (radiance.clamp_min(0) / self.scale).pow(1.0 / self.gamma)
        return (2 * f - 1).clamp(-1, 1)

    def to_radiance(self, x: torch.Tensor) -> torch.Tensor:
        """Prior space x in [-1, 1] -> linear HDR radiance; exact inverse of `to_prior` below the clamp."""
        base = ((x.clamp(-1, 1) + 1) / 2 / self.a).clamp_min(0)
        return self.scale * base.pow(self.gamma)

    def with_scale(self, scale: float) -> "ToneCurve":
        """Same curve with another radiance scale."""
        return ToneCurve(self.a, self.gamma, float(scale))


TONE_CURVES = {
    "outdoor": ToneCurve(a=0.5, gamma=2.4),
    "indoor": ToneCurve(a=0.9, gamma=6.0),
}
