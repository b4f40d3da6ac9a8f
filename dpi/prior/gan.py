"""A small style-modulated GAN over env maps, the `gan` method's prior (the paper's StyleGAN2-ADA baseline, scaled to
a 2-core CPU and named for what it is).

The generator maps z ~ N(0, I) through a mapping network to w, and w modulates every block of a convolutional
synthesis network (a per-channel gain from w, as StyleGAN's styles; one w per block is W+) that grows a learned
4 x 8 constant to the prior's 32 x 64 map in its encoding. Every convolution and upsampling pads across the sphere
(dpi.light.envmap.pad_equirect), so maps have no seam. The discriminator downsamples the same way. Training is the
non-saturating loss with a lazy R1 penalty on real maps; both see every batch through adaptive augmentation (ADA,
Karras et al. 2020): random rolls and flips (the paper's augmentations) and an exposure and white-balance change, each applied
with a probability p that rises while the discriminator's sign on real maps is above ADA_TARGET and falls below
it.
The data is the diffusion priors' training set (procedural maps with real panoramas mixed in, dpi.prior.reni).
"""

from __future__ import annotations

import copy
import json
import time
from dataclasses import asdict
from pathlib import Path

import torch
from torch import nn
from torch.nn import functional as F
from tqdm import tqdm

from dpi.io.settings import Count, Fraction, Rate, Weight, settings
from dpi.light.sphere_nn import EquirectConv, upsample
from dpi.light.tonecurve import Encoding, encoding_from_dict
from dpi.prior.baselines import export_checkpoint, read_checkpoint
from dpi.prior.data import EnvmapDataset, augment, median_target, recolour
from dpi.prior.train import ema_update, save_atomic

FORMAT = "dpi-gan-1"
"""the checkpoint format this module writes and reads"""
ADA_TARGET = 0.6
"""the discriminator's mean sign on real maps that adaptive augmentation holds (Karras et al.'s value)"""
ADA_SPEED = 20000.0
"""maps over which p can go from 0 to 1"""
LOG_EVERY = 10
"""optimiser steps between two lines of the training log"""
R1_EVERY = 4
"""discriminator steps between two R1 penalties, each weighed by this many (StyleGAN2's lazy regularisation)"""
CHECKPOINT_EVERY = 200
"""optimiser steps between two saves of the resumable checkpoint"""


@settings
class GANNetwork:
    """The networks' shape (stored in the checkpoint)."""

    latent: Count = 64
    """dimension of z and w"""
    channels: Count = 32
    """feature channels of every block"""
    height: Count = 32
    """the generated map's height H (maps are H x 2H; a power of two times 4)"""


@settings
class GANTraining:
    """How the GAN is trained (`dpi train-gan`)."""

    steps: Count = 4000
    """optimiser steps of each network in all (a resumed run continues to this count)"""
    batch_size: Count = 16
    """maps a step"""
    lr: Rate = 2e-3
    """Adam rate of both networks (betas 0, 0.99, as StyleGAN2)"""
    r1_weight: Weight = 0.1
    """gamma of the R1 penalty on real maps"""
    ema_decay: Fraction = 0.99
    """the generator that ships is this moving average of the trained one"""
    real_fraction: Fraction = 0.7
    """share of each batch drawn from the real panoramas, when given"""
    max_minutes: Rate | None = None
    """stop after this wall time (the checkpoint is written)"""
    seed: int = 0
    """the run's seed (batches, latents, augmentations)"""


class StyleBlock(nn.Module):
    """Upsample (but the first), convolve, modulate each channel by w, LeakyReLU."""

    def __init__(self, c_in: int, c_out: int, latent: int, up: bool):
        super().__init__()
        self.up, self.conv, self.style = up, EquirectConv(c_in, c_out, 3), nn.Linear(latent, c_out)
        nn.init.zeros_(self.style.weight)
        nn.init.ones_(self.style.bias)

    def forward(self, x: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
        x = self.conv(upsample(x) if self.up else x)
        return F.leaky_relu(x * self.style(w)[:, :, None, None], 0.2)


def levels(height: int) -> int:
    """Upsamplings from the 4-row constant to `height` rows."""
    count = 0
    while 4 * 2 ** count < height:
        count += 1
    if 4 * 2 ** count != height:
        raise ValueError(f"gan: height must be 4 times a power of two, got {height}")
    return count


class Generator(nn.Module):
    """z (B, latent) -> w (mapping) -> the map (B, 3, H, 2H) in the prior's encoding; `synthesis` takes W+ (B, blocks,
    latent)."""

    def __init__(self, network: GANNetwork):
        super().__init__()
        self.network, c, n = network, network.channels, network.latent
        self.mapping = nn.Sequential(nn.Linear(n, n), nn.LeakyReLU(0.2), nn.Linear(n, n), nn.LeakyReLU(0.2),
                                     nn.Linear(n, n))
        self.const = nn.Parameter(torch.randn(1, c, 4, 8))
        self.blocks = nn.ModuleList([StyleBlock(c, c, n, False)] +
                                    [StyleBlock(c, c, n, True) for _ in range(levels(network.height))])
        self.out = nn.Conv2d(c, 3, 1)

    @property
    def styles(self) -> int:
        """w's a map takes in W+: one per block."""
        return len(self.blocks)

    def synthesis(self, w_plus: torch.Tensor) -> torch.Tensor:
        """W+ (B, styles, latent) -> (B, 3, H, 2H) in [-1, 1]."""
        x = self.const.expand(w_plus.shape[0], -1, -1, -1)
        for i, block in enumerate(self.blocks):
            x = block(x, w_plus[:, i])
        return torch.tanh(self.out(x))

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        """z (B, latent) -> maps (B, 3, H, 2H)."""
        w = self.mapping(z)
        return self.synthesis(w[:, None].expand(-1, self.styles, -1))


class Discriminator(nn.Module):
    """(B, 3, H, 2H) -> (B,) logits: strided sphere-padded convolutions down to 4 x 8, then a linear layer."""

    def __init__(self, network: GANNetwork):
        super().__init__()
        c, layers = network.channels, [EquirectConv(3, network.channels, 3), nn.LeakyReLU(0.2)]
        for _ in range(levels(network.height)):
            layers += [EquirectConv(c, c, 3, stride=2), nn.LeakyReLU(0.2)]
        self.body, self.out = nn.Sequential(*layers), nn.Linear(c * 4 * 8, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.out(self.body(x).flatten(1))[:, 0]


def ada(x: torch.Tensor, p: float, encoding: Encoding, generator: torch.Generator) -> torch.Tensor:
    """Each map rolled and flipped (augment), and given an exposure and white balance (recolour), with probability p."""
    if p <= 0:
        return x
    keep = torch.rand(x.shape[0], generator=generator) >= p
    changed = recolour(augment(x, generator), encoding, generator)
    return torch.where(keep[:, None, None, None], x, changed)


class GAN:
    """A trained generator with what it was trained for."""

    def __init__(self, generator: Generator, family: str, encoding: Encoding, height: int, w_mean: torch.Tensor):
        self.generator, self.family, self.encoding, self.height = generator, family, encoding, height
        self.w_mean = w_mean
        """the mean w of the mapping network (where inversions of the truncation trick start)"""


def load_gan(path: str | Path, family: str | None = None, encoding: Encoding | None = None,
             height: int | None = None) -> GAN:
    """A GAN checkpoint, refused with its file named when it is missing, of another format, or trained for another
    family, encoding or map size than given."""
    ckpt = read_checkpoint(path, FORMAT, "GAN", "train-gan", family, encoding, height)
    generator = Generator(GANNetwork(**ckpt["network"]))
    generator.load_state_dict(ckpt["ema"])
    return GAN(generator.eval().requires_grad_(False), ckpt["family"], encoding_from_dict(ckpt["encoding"]),
               ckpt["height"], ckpt["w_mean"])


def train_gan(network: GANNetwork, cfg: GANTraining, maps: EnvmapDataset, out: str | Path,
              progress: bool = True) -> dict:
    """Train generator and discriminator (module notes), checkpointing to `out` (resumed when it exists) until
    `cfg.steps` or `cfg.max_minutes`; a line of the log (`out`.log.jsonl) every LOG_EVERY steps. Returns the last
    line."""
    if maps.height != network.height:
        raise ValueError(f"gan: the maps have {maps.height} rows, the network makes {network.height}")
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(cfg.seed)
    g, d = Generator(network), Discriminator(network)
    ema = copy.deepcopy(g).eval().requires_grad_(False)
    opt_g = torch.optim.Adam(g.parameters(), lr=cfg.lr, betas=(0.0, 0.99))
    opt_d = torch.optim.Adam(d.parameters(), lr=cfg.lr, betas=(0.0, 0.99))
    step, wall, p = 0, 0.0, 0.0
    if out.exists():
        ckpt = torch.load(out, map_location="cpu", weights_only=True)
        for module, key in ((g, "generator"), (d, "discriminator"), (ema, "ema")):
            module.load_state_dict(ckpt[key])
        opt_g.load_state_dict(ckpt["opt_g"])
        opt_d.load_state_dict(ckpt["opt_d"])
        step, wall, p = ckpt["step"], ckpt["wall_seconds"], ckpt["ada_p"]
    generator = torch.Generator().manual_seed(cfg.seed * 1_000_003 + step)
    start = time.perf_counter() - wall
    deadline = None if cfg.max_minutes is None else time.perf_counter() + 60 * cfg.max_minutes
    record: dict = {"step": step}

    def save() -> None:
        with torch.no_grad():
            w_mean = ema.mapping(torch.randn(4096, network.latent, generator=torch.Generator().manual_seed(0))).mean(0)
        save_atomic({"format": FORMAT, "family": maps.family, "encoding": maps.encoding.to_dict(),
                     "height": network.height, "median_target": median_target(maps.family, maps.encoding),
                     "network": asdict(network), "train": asdict(cfg), "ema": ema.state_dict(), "w_mean": w_mean,
                     "generator": g.state_dict(), "discriminator": d.state_dict(), "opt_g": opt_g.state_dict(),
                     "opt_d": opt_d.state_dict(), "ada_p": p, "step": step,
                     "wall_seconds": time.perf_counter() - start}, out)

    bar = tqdm(total=cfg.steps, initial=step, desc=f"train gan {maps.family}", disable=not progress)
    while step < cfg.steps and (deadline is None or time.perf_counter() < deadline):
        regularise = step % R1_EVERY == 0
        real = maps.batch(cfg.batch_size, generator).requires_grad_(regularise)
        z = torch.randn(cfg.batch_size, network.latent, generator=generator)
        fake = g(z)
        real_logits = d(ada(real, p, maps.encoding, generator))
        fake_logits = d(ada(fake.detach(), p, maps.encoding, generator))
        loss_d = F.softplus(fake_logits).mean() + F.softplus(-real_logits).mean()
        if regularise:
            (r1,) = torch.autograd.grad(real_logits.sum(), real, create_graph=True)
            loss_d = loss_d + 0.5 * cfg.r1_weight * R1_EVERY * r1.square().sum(dim=(1, 2, 3)).mean()
        opt_d.zero_grad(set_to_none=True)
        loss_d.backward()
        opt_d.step()
        loss_g = F.softplus(-d(ada(fake, p, maps.encoding, generator))).mean()
        opt_g.zero_grad(set_to_none=True)
        loss_g.backward()
        opt_g.step()
        ema_update(ema, g, cfg.ema_decay)
        sign = float(real_logits.detach().sign().mean())
        p = min(max(p + (1.0 if sign > ADA_TARGET else -1.0) * cfg.batch_size / ADA_SPEED, 0.0), 1.0)
        step += 1
        bar.update(1)
        if step % LOG_EVERY == 0:
            record = {"step": step, "seconds": round(time.perf_counter() - start, 2), "loss_d": round(loss_d.item(), 5),
                      "loss_g": round(loss_g.item(), 5), "real_sign": round(sign, 3), "ada_p": round(p, 3)}
            bar.set_postfix(d=f"{record['loss_d']:.3f}", g=f"{record['loss_g']:.3f}", p=f"{p:.2f}")
            with open(out.with_suffix(".log.jsonl"), "a") as log:
                log.write(json.dumps(record) + "\n")
        if step % CHECKPOINT_EVERY == 0:
            save()
    bar.close()
    save()
    return record


def export_gan(checkpoint: str | Path, dest: str | Path) -> None:
    """The shippable generator (its moving average) and what it was trained for, without the discriminator and the
    optimisers."""
    export_checkpoint(checkpoint, dest, ("generator", "discriminator", "opt_g", "opt_d"))
