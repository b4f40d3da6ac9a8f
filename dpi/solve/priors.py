"""Hand-crafted illumination priors of the paper's comparison, as penalties on an env map (H, 2H, 3).

- `global_norm`: the map's median luminance is pulled to a reference (fixes the global scale);
- `smoothness`: total variation of log(1 + L), wrapping around the azimuth;
- `chromaticity`: mean squared deviation of each texel's chromaticity from grey (white light).
`none` has no penalty.
"""

from __future__ import annotations

from typing import Callable

import torch

from dpi.io.images import luminance


def global_norm_penalty(env: torch.Tensor, reference_median: float) -> torch.Tensor:
    """(log median luminance - log reference)^2."""
    median = luminance(env).flatten().median().clamp_min(1e-8)
    return (median.log() - torch.log(torch.tensor(reference_median).clamp_min(1e-8))).square()


def smoothness_penalty(env: torch.Tensor) -> torch.Tensor:
    """Anisotropic total variation of log(1 + L), horizontally periodic."""
    x = torch.log1p(env.clamp_min(0))
    dx = (torch.roll(x, -1, dims=1) - x).abs().mean()
    dy = (x[1:] - x[:-1]).abs().mean()
    return dx + dy


def chromaticity_penalty(env: torch.Tensor) -> torch.Tensor:
    """Mean squared distance of rgb / (r + g + b) from (1/3, 1/3, 1/3)."""
    chroma = env / env.sum(-1, keepdim=True).clamp_min(1e-8)
    return (chroma - 1.0 / 3.0).square().sum(-1).mean()


PRIOR_NAMES = ("none", "global_norm", "smoothness", "chromaticity")


def make_prior(name: str, reference_env: torch.Tensor) -> Callable[[torch.Tensor], torch.Tensor] | None:
    """Penalty function of a named prior; `reference_env` supplies global_norm's reference median."""
    if name == "none":
        return None
    if name == "global_norm":
        reference = float(luminance(reference_env).median())
        return lambda env: global_norm_penalty(env, reference)
    if name == "smoothness":
        return smoothness_penalty
    if name == "chromaticity":
        return chromaticity_penalty
    raise ValueError(f"unknown prior {name!r}; choose from {', '.join(PRIOR_NAMES)}")
