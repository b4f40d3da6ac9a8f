"""Invertible encodings between linear HDR radiance and the prior's [-1, 1] image space.

Two encodings, with one interface (`to_prior`, `to_radiance`, `with_scale`, `to_dict`):

- `ToneCurve`, the paper's: x = 2 f(L / scale) - 1 with f(L) = a L^(1/gamma), clamped at x = 1;
  back: L = scale ((x + 1) / 2 / a)^gamma. Paper values: outdoor a=0.5, gamma=2.4; indoor a=0.9,
  gamma=6. The clamp caps a map at (1/a)^gamma times the radiance at x = 0: no room for a sun.
- `LogEncoding`, for real HDR: x = clip((ln(L / scale) - offset) / width, -1, 1); back:
  L = scale exp(offset + width x). With the map's median at `scale` the defaults span
  exp(-5) .. exp(10), about 7e-3 .. 2.2e4 times the median, so a sun fits (RENI++ and Text2Light
  also work in log radiance).

A checkpoint stores `to_dict()` of its encoding; `encoding_from_dict` reads both kinds back (a
dict without `kind` is the paper's curve, as in checkpoints written before the log encoding).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Protocol

import torch

TINY_RADIANCE = 1e-30
"""floor before the logarithm: black texels map to x = -1 instead of -inf"""


class Encoding(Protocol):
    """What the prior and its samplers need of an encoding."""

    scale: float

    def to_prior(self, radiance: torch.Tensor) -> torch.Tensor: ...

    def to_radiance(self, x: torch.Tensor) -> torch.Tensor: ...

    def log_to_prior(self, log_radiance: torch.Tensor) -> torch.Tensor: ...

    def with_scale(self, scale: float) -> "Encoding": ...

    def to_dict(self) -> dict[str, Any]: ...


@dataclass(frozen=True)
class ToneCurve:
    """The paper's curve f(L) = a L^(1/gamma) with a per-scene radiance scale."""

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

    def log_to_prior(self, log_radiance: torch.Tensor) -> torch.Tensor:
        """`to_prior` of exp(log_radiance) without the clamp: smooth everywhere, for penalties on x."""
        return 2 * self.a * torch.exp((log_radiance - math.log(self.scale)) / self.gamma) - 1

    def with_scale(self, scale: float) -> "ToneCurve":
        """Same curve with another radiance scale."""
        return replace(self, scale=float(scale))

    def to_dict(self) -> dict[str, Any]:
        """The curve's parameters for a checkpoint (without the per-scene scale)."""
        return {"kind": "power", "a": self.a, "gamma": self.gamma}


@dataclass(frozen=True)
class LogEncoding:
    """x = clip((ln(L / scale) - offset) / width, -1, 1): log radiance around the map's median."""

    offset: float = 2.5
    width: float = 7.5
    scale: float = 1.0

    def to_prior(self, radiance: torch.Tensor) -> torch.Tensor:
        """Linear HDR radiance (>= 0) -> prior space x in [-1, 1] (clamped outside the range)."""
        log_l = torch.log(radiance.clamp_min(TINY_RADIANCE) / self.scale)
        return ((log_l - self.offset) / self.width).clamp(-1, 1)

    def to_radiance(self, x: torch.Tensor) -> torch.Tensor:
        """Prior space x in [-1, 1] -> linear HDR radiance, smooth (exp) and exact inside the range."""
        return self.scale * torch.exp(self.offset + self.width * x.clamp(-1, 1))

    def log_to_prior(self, log_radiance: torch.Tensor) -> torch.Tensor:
        """`to_prior` of exp(log_radiance) without the clip: affine, for penalties on x."""
        return (log_radiance - math.log(self.scale) - self.offset) / self.width

    def with_scale(self, scale: float) -> "LogEncoding":
        """Same encoding with another radiance scale."""
        return replace(self, scale=float(scale))

    def to_dict(self) -> dict[str, Any]:
        """The encoding's parameters for a checkpoint (without the per-scene scale)."""
        return {"kind": "log", "offset": self.offset, "width": self.width}

    @property
    def range(self) -> tuple[float, float]:
        """Smallest and largest radiance it represents, in units of `scale`."""
        return math.exp(self.offset - self.width), math.exp(self.offset + self.width)


def encoding_from_dict(values: dict[str, Any]) -> Encoding:
    """The encoding a checkpoint recorded (`kind` log or power; no kind: the paper's power curve)."""
    values = {k: v for k, v in values.items() if k != "median_target"}
    kind = values.pop("kind", "power")
    if kind == "power":
        return ToneCurve(float(values["a"]), float(values["gamma"]))
    if kind == "log":
        return LogEncoding(float(values["offset"]), float(values["width"]))
    raise ValueError(f"unknown prior encoding {kind!r}; known: power, log")


TONE_CURVES = {
    "outdoor": ToneCurve(a=0.5, gamma=2.4),
    "indoor": ToneCurve(a=0.9, gamma=6.0),
}
"""The paper's curves per family (encoding "paper")."""

ENCODINGS = ("log", "paper")
"""Encodings a prior can be trained in: log radiance (the default) or the paper's tone curve."""


def family_encoding(family: str, encoding: str = "log") -> Encoding:
    """The encoding of a family's prior: the log encoding, or the paper's curve of that family."""
    if encoding == "log":
        return LogEncoding()
    if encoding == "paper":
        return TONE_CURVES[family]
    raise ValueError(f"unknown prior encoding {encoding!r}; choose from {', '.join(ENCODINGS)}")
