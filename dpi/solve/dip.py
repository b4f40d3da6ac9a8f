"""Deep image prior (`dip`, Ulyanov et al. 2018) on the illumination: a randomly initialised CNN
generates the environment map, and its weights, not the texels, are fitted to the views.

The network maps a fixed random code z (uniform in [0, 0.1), drawn with the weights from the
sample's seed) through an encoder-decoder with skip connections (Ulyanov's "skip" architecture:
convolution, batch norm over the one map's texels, LeakyReLU) to an offset of the map's
log-radiance. Every convolution and upsampling pads across the sphere (circularly in azimuth,
across the poles), so generated maps have no seam.

The prior is implicit: a convolutional generator reproduces smooth, natural structure long
before noise, so the architecture and early stopping (`iterations`) take the place of the other
priors' penalty. There is no prior term, hence no weight to balance against the data term.

Like the other optimisation-based methods a sample starts from the initialisation: its roughness
and metallic, a grey albedo, and a network first fitted (`warmup_iterations` Adam steps, no
rendering) to the init map. The seed's weights and code make samples differ.
"""

from __future__ import annotations

from dataclasses import field
from pathlib import Path
from typing import Annotated

import torch
from pydantic import Field
from torch import nn

from dpi.io.settings import Count, Steps, settings
from dpi.light.sphere_nn import EquirectConv, upsample
from dpi.solve.decomposition import Decomposition
from dpi.solve.init import starting_materials
from dpi.solve.optimize import (LOG_ENV_RANGE, EnvModel, OptimizeConfig, fit_env_model, fit_to_map, flat_config,
                                method_config_from_dict)
from dpi.solve.problem import InverseProblem
from dpi.solve.trace import Trace

SKIP_CHANNELS = 4
"""channels of each skip connection (Ulyanov et al.'s value)"""
CODE_SCALE = 0.1
"""the input code is uniform in [0, CODE_SCALE)"""


@settings
class DIPConfig:
    """Settings of the `dip` method."""

    optimize: OptimizeConfig = field(
        default_factory=lambda: OptimizeConfig(iterations=150, views_per_step=2, lr_env=1e-2))
    """Adam settings; lr_env is the learning rate of the network's weights"""
    channels: Count = 32
    """feature channels at every level of the network"""
    depth: Annotated[int, Field(ge=1, le=8)] = 4
    """downsampling levels (fewer when env_height has fewer factors of 2)"""
    code_channels: Count = 16
    """channels of the fixed random input code"""
    warmup_iterations: Steps = 100
    """Adam steps fitting the network to the init map before the rendering loss (0: start from its mean level)"""

    @classmethod
    def from_dict(cls, values: dict) -> "DIPConfig":
        """Config from a flat `method_params.dip` dict: OptimizeConfig keys plus this class's own."""
        return method_config_from_dict(cls, values)


def network_levels(height: int, depth: int) -> int:
    """Downsampling levels of an H x 2H map: at most `depth`, each halving H exactly."""
    levels = 0
    while levels < depth and height % 2 ** (levels + 1) == 0:
        levels += 1
    if levels == 0:
        raise ValueError(f"dip: env_height must be even (got {height}) for the network to downsample it")
    return levels


def conv_block(c_in: int, c_out: int, kernel: int, stride: int = 1) -> nn.Sequential:
    """Equirect convolution, batch norm (always the current map's statistics: training is stable at
    Adam's usual learning rates, which it is not without), LeakyReLU(0.2)."""
    return nn.Sequential(EquirectConv(c_in, c_out, kernel, stride),
                         nn.BatchNorm2d(c_out, track_running_stats=False), nn.LeakyReLU(0.2))


class DeepImagePrior(EnvModel):
    """log L = base + g_w(z): an encoder-decoder g with weights w over a fixed code z, (H, 2H, 3) out."""

    def __init__(self, height: int, base: torch.Tensor, cfg: DIPConfig, seed: int):
        super().__init__()
        levels = network_levels(height, cfg.depth)
        c = cfg.channels
        inputs = [cfg.code_channels] + [c] * (levels - 1)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            self.register_buffer("code", CODE_SCALE * torch.rand(1, cfg.code_channels, height, 2 * height))
            self.down = nn.ModuleList(nn.Sequential(conv_block(i, c, 3, stride=2), conv_block(c, c, 3)) for i in inputs)
            self.skip = nn.ModuleList(conv_block(i, SKIP_CHANNELS, 1) for i in inputs)
            self.up = nn.ModuleList(nn.Sequential(conv_block(c + SKIP_CHANNELS, c, 3), conv_block(c, c, 1))
                                    for _ in inputs)
            self.out = nn.Conv2d(c, 3, 1)
        self.register_buffer("base", base.detach().clone())

    def forward(self) -> torch.Tensor:
        """The generated log-radiance map (H, 2H, 3), clamped to LOG_ENV_RANGE."""
        x, skips = self.code, []
        for down, skip in zip(self.down, self.skip):
            skips.append(skip(x))
            x = down(x)
        for up, s in zip(reversed(self.up), reversed(skips)):
            x = up(torch.cat([upsample(x), s], dim=1))
        return (self.base + self.out(x)[0].permute(1, 2, 0)).clamp(*LOG_ENV_RANGE)


def dip_sample(problem: InverseProblem, init: Decomposition, cfg: DIPConfig, seed: int,
               progress: bool = True, checkpoint: Path | None = None) -> Decomposition:
    """One `dip` sample: the network (seeded) warmed up on the init map, then fitted jointly with the
    materials (`checkpoint`: the joint fit's resume file; the short warm-up is rerun)."""
    target = init.env.clamp_min(1e-6).log()
    model = DeepImagePrior(target.shape[0], target.mean(dim=(0, 1)), cfg, seed)
    warmup_error = fit_to_map(model, target, cfg.warmup_iterations, cfg.optimize.lr_env)
    trace = Trace(info={"method": "dip", "seed": seed, "config": flat_config(cfg), "prior_weight": 0.0,
                        "prior": "implicit: network architecture and early stopping (iterations)",
                        "network_parameters": sum(p.numel() for p in model.parameters()),
                        "warmup_error": warmup_error})
    log_env, materials = fit_env_model(problem, model, starting_materials(init), cfg.optimize, seed, trace,
                                       progress=progress, checkpoint=checkpoint)
    return Decomposition(log_env.exp(), materials, trace)
