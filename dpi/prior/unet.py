"""The guided-diffusion UNet (Dhariwal & Nichol 2021), re-implemented key for key.

Module names and parameter shapes follow openai/guided-diffusion's `UNetModel`, so a state dict
saved there loads here strictly for the same hyper-parameters: `time_embed.{0,2}`,
`input_blocks.N.M`, `middle_block.{0,1,2}`, `output_blocks.N.M`, `out.{0,2}`; ResBlocks hold
`in_layers.{0,2}`, `emb_layers.1`, `out_layers.{0,3}` and `skip_connection` (when channels
change); attention blocks hold `norm`, `qkv`, `proj_out`. Spatial sizes only need to be divisible
by 2^(levels-1), so H x 2H env maps work as well as squares.
"""

from __future__ import annotations

import math
from dataclasses import asdict
from pathlib import Path
from typing import Annotated

import torch
from pydantic import Field
from torch import nn
from torch.nn import functional as F

from dpi.io.settings import Count, Loose, settings


CHANNELS = 3
"""colour channels of the maps the network sees"""
GUIDED_DIFFUSION_FIXED = {"in_channels": CHANNELS, "num_heads_upsample": -1, "use_scale_shift_norm": True,
                          "resblock_updown": True, "use_new_attention_order": False, "learn_sigma": True}
"""guided-diffusion's flags that the authors' checkpoints and dpi's share, with their one value: dpi's UNet
implements only that (a checkpoint's config may list them); with learn_sigma the network outputs eps and the
variance interpolation v"""
TRAINING_ONLY = ("dropout",)
"""guided-diffusion's flags that change training only (a checkpoint's config may list them; sampling ignores them)"""


@settings(frozen=True)
class UNetConfig:
    """Hyper-parameters of guided-diffusion's UNetModel (names as in its script_util flags)."""

    image_size: Annotated[int, Field(ge=8)] = 32  # height H; only used to turn attention resolutions into downsample factors
    num_channels: Count = 64  # model_channels
    num_res_blocks: Count = 2
    channel_mult: Annotated[tuple[int, ...], Loose] = (1, 2, 2)
    attention_ds: Annotated[tuple[int, ...], Loose] = (4,)  # downsample factors with attention (image_size // resolution)
    num_heads: Count = 4
    num_head_channels: Annotated[int, Field(ge=-1)] = -1  # channels per head; overrides num_heads when != -1
    norm_groups: Count = 32  # GroupNorm groups (guided-diffusion: 32); no parameter depends on it. Keep several
    # channels per group: with one channel per group the output head cannot carry the image mean, and
    # samples get strong random colour casts

    @property
    def out_channels(self) -> int:
        """6 output channels: eps and the variance interpolation v."""
        return 2 * CHANNELS

    def to_dict(self) -> dict:
        """Plain dict (JSON / checkpoint friendly)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "UNetConfig":
        """Inverse of `to_dict` (lists become tuples); guided-diffusion's flags of GUIDED_DIFFUSION_FIXED may be
        present, with the one value this network implements."""
        d = {k: v for k, v in d.items() if k not in TRAINING_ONLY}
        for key, value in GUIDED_DIFFUSION_FIXED.items():
            if key in d and d.pop(key) != value:
                raise CheckpointError(f"network flag {key} must be {value} (the one dpi's UNet implements)")
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})


def attention_ds_from_resolutions(image_size: int, resolutions: str) -> tuple[int, ...]:
    """guided-diffusion's flag '32,16,8' at image_size 256 -> downsample factors (8, 16, 32)."""
    return tuple(image_size // int(r) for r in resolutions.split(","))


PAPER_CONFIG = UNetConfig(
    image_size=256, num_channels=256, num_res_blocks=3, channel_mult=(1, 1, 2, 2, 4, 4),
    attention_ds=attention_ds_from_resolutions(256, "32,16,8"), num_heads=4, num_head_channels=64,
)
"""The authors' indoor/outdoor checkpoints (flags of configs/model_config_{indoor,outdoor}.yaml in LinjieLyu/DPI)."""

SMALL_CONFIGS = {
    "tiny": UNetConfig(image_size=16, num_channels=8, num_res_blocks=1, channel_mult=(1, 2), attention_ds=(2,),
                       num_heads=2, norm_groups=4),
    "small_32x64": UNetConfig(image_size=32, num_channels=32, num_res_blocks=1, channel_mult=(1, 2, 2, 2),
                              attention_ds=(4, 8), num_head_channels=32, norm_groups=8),
    "base_32x64": UNetConfig(image_size=32, num_channels=64, num_res_blocks=1, channel_mult=(1, 2, 2, 2),
                             attention_ds=(4, 8), num_head_channels=32, norm_groups=16),
    "base_64x128": UNetConfig(image_size=64, num_channels=64, num_res_blocks=1, channel_mult=(1, 2, 2, 2),
                              attention_ds=(4, 8), num_head_channels=32, norm_groups=16),
    "medium_32x64": UNetConfig(image_size=32, num_channels=64, num_res_blocks=2, channel_mult=(1, 2, 2, 2),
                               attention_ds=(4, 8), num_head_channels=32, norm_groups=16),
}
"""CPU-sized configs: 'tiny' for tests, 'small_32x64' (the earlier paper-curve CPU models, see the model card),
'base_32x64' for the log-radiance models trained on a GPU (their sizes and costs: the model card); 'base_64x128' is
the same network on 64 x 128 maps (same weights, attention at 16 x 32 and 8 x 16), so a 32 x 64 prior can start its
run."""


def timestep_embedding(t: torch.Tensor, dim: int, max_period: float = 10000.0) -> torch.Tensor:
    """Sinusoidal embedding (N, dim) of timesteps t (N,): [cos(t f_i), sin(t f_i)], f_i = max_period^(-i/half)."""
    half = dim // 2
    freqs = torch.exp(-math.log(max_period) * torch.arange(half, dtype=torch.float32, device=t.device) / half)
    args = t[:, None].float() * freqs[None]
    emb = torch.cat([torch.cos(args), torch.sin(args)], dim=-1)
    return F.pad(emb, (0, 1)) if dim % 2 else emb


class GroupNorm32(nn.GroupNorm):
    """GroupNorm computed in float32 (as guided-diffusion, for fp16 weights)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return super().forward(x.float()).type(x.dtype)


def zero_module(module: nn.Module) -> nn.Module:
    """Zero a module's parameters (output convs start as the identity residual)."""
    for p in module.parameters():
        nn.init.zeros_(p)
    return module


class TimestepSequential(nn.Sequential):
    """Sequential that passes the time embedding to the layers that take one (ResBlocks)."""

    def forward(self, x: torch.Tensor, emb: torch.Tensor) -> torch.Tensor:  # type: ignore[override]
        for layer in self:
            x = layer(x, emb) if isinstance(layer, ResBlock) else layer(x)
        return x


class ResBlock(nn.Module):
    """Residual block conditioned on the time embedding, optionally resampling (guided-diffusion ResBlock)."""

    def __init__(self, channels: int, emb_channels: int, out_channels: int, cfg: UNetConfig,
                 up: bool = False, down: bool = False):
        super().__init__()
        self.in_layers = nn.Sequential(GroupNorm32(cfg.norm_groups, channels), nn.SiLU(),
                                       nn.Conv2d(channels, out_channels, 3, padding=1))
        self.resample = nn.Upsample(scale_factor=2, mode="nearest") if up else nn.AvgPool2d(2) if down else nn.Identity()
        self.emb_layers = nn.Sequential(nn.SiLU(), nn.Linear(emb_channels, 2 * out_channels))
        self.out_layers = nn.Sequential(
            GroupNorm32(cfg.norm_groups, out_channels), nn.SiLU(), nn.Identity(),  # guided-diffusion's dropout
            zero_module(nn.Conv2d(out_channels, out_channels, 3, padding=1)))
        self.skip_connection = nn.Identity() if out_channels == channels else nn.Conv2d(channels, out_channels, 1)

    def forward(self, x: torch.Tensor, emb: torch.Tensor) -> torch.Tensor:
        h = self.in_layers[:-1](x)
        h = self.in_layers[-1](self.resample(h))
        x = self.resample(x)
        emb_out = self.emb_layers(emb).type(h.dtype)[..., None, None]
        scale, shift = emb_out.chunk(2, dim=1)  # scale-shift norm
        h = self.out_layers[1:](self.out_layers[0](h) * (1 + scale) + shift)
        return self.skip_connection(x) + h


class AttentionBlock(nn.Module):
    """Multi-head self-attention over all spatial positions, residual (guided-diffusion AttentionBlock)."""

    def __init__(self, channels: int, num_heads: int, num_head_channels: int, cfg: UNetConfig):
        super().__init__()
        self.num_heads = channels // num_head_channels if num_head_channels != -1 else num_heads
        if channels % self.num_heads:
            raise ValueError(f"{channels} channels do not split into {self.num_heads} heads")
        self.norm = GroupNorm32(cfg.norm_groups, channels)
        self.qkv = nn.Conv1d(channels, 3 * channels, 1)
        self.proj_out = zero_module(nn.Conv1d(channels, channels, 1))

    def attention(self, qkv: torch.Tensor) -> torch.Tensor:
        """Attention (B, C, T) from stacked qkv (B, 3C, T), heads split before q/k/v (guided-diffusion's legacy
        order, which its checkpoints use)."""
        b, width, length = qkv.shape
        ch = width // (3 * self.num_heads)
        q, k, v = qkv.reshape(b * self.num_heads, 3 * ch, length).split(ch, dim=1)
        scale = ch ** -0.25
        weight = torch.einsum("bct,bcs->bts", q * scale, k * scale).float().softmax(dim=-1).type(qkv.dtype)
        return torch.einsum("bts,bcs->bct", weight, v).reshape(b, -1, length)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, c, *spatial = x.shape
        x = x.reshape(b, c, -1)
        h = self.proj_out(self.attention(self.qkv(self.norm(x))))
        return (x + h).reshape(b, c, *spatial)


class UNetModel(nn.Module):
    """eps_theta(x_t, t): (B, C, H, W) image and (B,) timesteps -> (B, C or 2C, H, W)."""

    def __init__(self, cfg: UNetConfig):
        super().__init__()
        self.config = cfg
        ch = cfg.num_channels * cfg.channel_mult[0]
        emb_dim = 4 * cfg.num_channels
        self.time_embed = nn.Sequential(nn.Linear(cfg.num_channels, emb_dim), nn.SiLU(), nn.Linear(emb_dim, emb_dim))
        self.input_blocks = nn.ModuleList([TimestepSequential(nn.Conv2d(CHANNELS, ch, 3, padding=1))])
        skip_channels = [ch]
        ds = 1
        for level, mult in enumerate(cfg.channel_mult):
            for _ in range(cfg.num_res_blocks):
                layers: list[nn.Module] = [ResBlock(ch, emb_dim, mult * cfg.num_channels, cfg)]
                ch = mult * cfg.num_channels
                if ds in cfg.attention_ds:
                    layers.append(AttentionBlock(ch, cfg.num_heads, cfg.num_head_channels, cfg))
                self.input_blocks.append(TimestepSequential(*layers))
                skip_channels.append(ch)
            if level != len(cfg.channel_mult) - 1:
                self.input_blocks.append(TimestepSequential(ResBlock(ch, emb_dim, ch, cfg, down=True)))
                skip_channels.append(ch)
                ds *= 2
        self.middle_block = TimestepSequential(
            ResBlock(ch, emb_dim, ch, cfg), AttentionBlock(ch, cfg.num_heads, cfg.num_head_channels, cfg),
            ResBlock(ch, emb_dim, ch, cfg))
        self.output_blocks = nn.ModuleList()
        for level, mult in reversed(list(enumerate(cfg.channel_mult))):
            for i in range(cfg.num_res_blocks + 1):
                layers = [ResBlock(ch + skip_channels.pop(), emb_dim, mult * cfg.num_channels, cfg)]
                ch = mult * cfg.num_channels
                if ds in cfg.attention_ds:
                    layers.append(AttentionBlock(ch, cfg.num_heads, cfg.num_head_channels, cfg))
                if level and i == cfg.num_res_blocks:
                    layers.append(ResBlock(ch, emb_dim, ch, cfg, up=True))
                    ds //= 2
                self.output_blocks.append(TimestepSequential(*layers))
        self.out = nn.Sequential(GroupNorm32(cfg.norm_groups, ch), nn.SiLU(),
                                 zero_module(nn.Conv2d(ch, cfg.out_channels, 3, padding=1)))

    def forward(self, x: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        """Model output (B, out_channels, H, W); H and W must be divisible by 2^(levels-1)."""
        factor = 2 ** (len(self.config.channel_mult) - 1)
        if x.shape[-2] % factor or x.shape[-1] % factor:
            raise ValueError(f"input size {tuple(x.shape[-2:])} is not divisible by {factor}")
        emb = self.time_embed(timestep_embedding(t, self.config.num_channels).to(x.dtype))
        skips = []
        h = x
        for block in self.input_blocks:
            h = block(h, emb)
            skips.append(h)
        h = self.middle_block(h, emb)
        for block in self.output_blocks:
            h = block(torch.cat([h, skips.pop()], dim=1), emb)
        return self.out(h)


class CheckpointError(ValueError):
    """A checkpoint does not match the model: missing/unexpected key or wrong shape (named)."""


def checkpoint_state_dict(obj: dict, use_ema: bool = True) -> dict:
    """The model weights inside a raw guided-diffusion state dict or a dpi checkpoint dict."""
    if "model" in obj and isinstance(obj["model"], dict):
        return obj["ema"] if use_ema and obj.get("ema") is not None else obj["model"]
    return obj


def load_state_dict_strict(model: nn.Module, state: dict) -> None:
    """Copy `state` into `model`; raise CheckpointError naming the first missing, unexpected or mis-shaped key."""
    expected = model.state_dict()
    missing = sorted(set(expected) - set(state))
    unexpected = sorted(set(state) - set(expected))
    if missing:
        raise CheckpointError(f"checkpoint lacks key {missing[0]!r} ({len(missing)} missing in all)")
    if unexpected:
        raise CheckpointError(f"checkpoint has unexpected key {unexpected[0]!r} ({len(unexpected)} unexpected in all)")
    for key, value in expected.items():
        if tuple(state[key].shape) != tuple(value.shape):
            raise CheckpointError(f"key {key!r} has shape {tuple(state[key].shape)}, model expects {tuple(value.shape)}")
    model.load_state_dict({k: v.to(expected[k].dtype) for k, v in state.items()}, strict=True)


def load_checkpoint(path: str | Path, config: UNetConfig | None = None, use_ema: bool = True,
                    device: str | torch.device = "cpu") -> UNetModel:
    """UNet in eval mode from a guided-diffusion `.pt` (config required) or a dpi checkpoint (config stored)."""
    obj = torch.load(path, map_location="cpu", weights_only=True)
    if config is None:
        if "config" not in obj:
            raise CheckpointError(f"{path}: raw state dict without a stored config; pass the UNetConfig")
        config = UNetConfig.from_dict(obj["config"])
    model = UNetModel(config)
    try:
        load_state_dict_strict(model, checkpoint_state_dict(obj, use_ema))
    except CheckpointError as exc:
        raise CheckpointError(f"{path}: {exc}") from exc
    return model.to(device).eval()


def count_parameters(model: nn.Module) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)

