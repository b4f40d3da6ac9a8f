"""Env maps between the scene and the diffusion prior's image space (shared by `dps` and `sds`).

A scene map is (H, 2H, 3) radiance at the problem's resolution; a prior image is (1, 3, h, 2h) in
[-1, 1] at the prior's. The radiance scale s (scene radiance per unit of the prior's normalised
radiance) is estimated once per sample from the init map, like the normalisation of the prior's
training maps; maps are resampled by area going down and bilinearly otherwise.
"""

from __future__ import annotations

import torch

from dpi.prior.data import radiance_scale
from dpi.prior.sample import Prior


def estimate_radiance_scale(init_env: torch.Tensor, prior: Prior) -> float:
    """Scene radiance per unit of the prior's normalised radiance: the init map's median luminance
    over the median the prior was trained with (the same normalisation as its training maps)."""
    return radiance_scale(init_env.permute(2, 0, 1), prior.median_target)


def resample_env(radiance: torch.Tensor, height: int) -> torch.Tensor:
    """(1, 3, h, 2h) radiance -> (height, 2 height, 3), bilinear (a 2x2 average when halving)."""
    if radiance.shape[-2] != height:
        radiance = torch.nn.functional.interpolate(radiance, size=(height, 2 * height), mode="bilinear",
                                                   align_corners=False)
    return radiance[0].permute(1, 2, 0)


def prior_to_env(x0: torch.Tensor, prior: Prior, scale: float, height: int) -> torch.Tensor:
    """Prior image (1, 3, h, w) -> scene env map (H, 2H, 3) in radiance, resampled to `height`."""
    return resample_env(scale * prior.encoding.to_radiance(x0), height)


def env_to_prior(env: torch.Tensor, prior: Prior, scale: float) -> torch.Tensor:
    """Scene env map (H, 2H, 3) -> prior image (1, 3, h, 2h): area-resampled, divided by `scale`, encoded."""
    radiance = torch.nn.functional.interpolate(env.permute(2, 0, 1)[None], size=(prior.height, 2 * prior.height),
                                               mode="area")
    return prior.encoding.with_scale(scale).to_prior(radiance)
