"""RENI (Gardner et al., NeurIPS 2022): a rotation-equivariant neural field of illumination, the `reni` method's prior.

A map is a latent Z of N vectors in R^3 and a decoder f(Z, d) -> x, the map in the prior's encoding, for every
direction d. The decoder sees Z and d only through quantities that rotations and mirrorings about the up axis (+Y)
keep: the Gram matrix of Z's horizontal parts, their products with d's, Z's heights and d's. Turning Z about the up
axis therefore turns the map (`rotate_latent`), and mirroring Z mirrors it: the paper's augmentations (rolls and
flips) are in the model, not in the data. The decoder is a SIREN (sine activations). It is trained as a variational
auto-decoder: each training map has a Gaussian over its latent, fitted with the decoder, with a KL term to N(0, I).
The latents settle at the scale the sine layers decode smoothly, below the KL's unit one, so the prior an unseen map's
latent is drawn and fitted under (dpi.solve.reni) is the training latents' own: isotropic, of their RMS
(`latent_std`, stored with the decoder). A map is decoded at the training maps' size and resampled across the sphere to
the problem's: the field holds no finer detail than they do.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict
from pathlib import Path

import torch
from torch import nn
from tqdm import tqdm

from dpi.io.settings import Count, Fraction, Rate, Weight, settings
from dpi.light.envmap import texel_directions, texel_solid_angles
from dpi.light.sphere_nn import resample_rows
from dpi.light.tonecurve import Encoding, encoding_from_dict
from dpi.prior.baselines import export_checkpoint, read_checkpoint
from dpi.prior.data import EnvmapDataset, median_target
from dpi.prior.train import save_atomic

FORMAT = "dpi-reni-1"
"""the checkpoint format this module writes and reads"""
FIRST_OMEGA = 30.0
"""the first sine layer's frequency (SIREN's w0)"""
LOG_EVERY = 10
"""optimiser steps between two lines of the training log"""
CHECKPOINT_EVERY = 100
"""optimiser steps between two saves of the resumable checkpoint"""


@settings
class RENINetwork:
    """The decoder's shape (stored in its checkpoint)."""

    latents: Count = 16
    """N: vectors in R^3 of a map's latent"""
    width: Count = 128
    """units of every sine layer"""
    layers: Count = 4
    """sine layers"""


@settings
class RENITraining:
    """How a RENI decoder is trained (`dpi train-reni`)."""

    steps: Count = 2000
    """optimiser steps in all (a resumed run continues to this count)"""
    batch_size: Count = 16
    """maps a step"""
    directions: Count = 512
    """directions of each map a step sees, drawn by solid angle"""
    lr: Rate = 1e-4
    """Adam rate of the decoder"""
    lr_latent: Rate = 1e-2
    """Adam rate of the training maps' latents"""
    kl_weight: Weight = 1e-4
    """weight of the latents' KL to N(0, I) per latent number, against the mean squared error in prior space"""
    real_fraction: Fraction = 0.7
    """share of each batch drawn from the real panoramas, when given"""
    max_minutes: Rate | None = None
    """stop after this wall time (the checkpoint is written)"""
    seed: int = 0
    """the run's seed (the decoder's and latents' start, batches, directions)"""


def invariants(z: torch.Tensor, d: torch.Tensor) -> torch.Tensor:
    """The decoder's input for latents z (B, N, 3) and directions d (B, M, 3): per direction, the upper triangle of the
    Gram matrix of z's horizontal (x, z) parts, their products with d's, z's heights and d's (B, M, N(N+1)/2 + 2N + 1);
    unchanged when z and d turn or mirror together about +Y."""
    zh, dh = z[..., [0, 2]], d[..., [0, 2]]
    n = z.shape[1]
    rows, cols = torch.triu_indices(n, n)
    gram = (zh @ zh.transpose(1, 2))[:, rows, cols]
    m = d.shape[1]
    return torch.cat([gram[:, None].expand(-1, m, -1), dh @ zh.transpose(1, 2), z[..., 1][:, None].expand(-1, m, -1),
                      d[..., 1:2]], dim=-1)


class Sine(nn.Module):
    """A SIREN layer sin(omega (W x + b)), initialised as Sitzmann et al. 2020."""

    def __init__(self, c_in: int, c_out: int, omega: float, first: bool):
        super().__init__()
        self.omega, self.linear = omega, nn.Linear(c_in, c_out)
        bound = 1.0 / c_in if first else math.sqrt(6.0 / c_in) / omega
        nn.init.uniform_(self.linear.weight, -bound, bound)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.sin(self.omega * self.linear(x))


class RENIDecoder(nn.Module):
    """f(Z, d): the map's value in the prior's encoding at each direction (module notes)."""

    def __init__(self, network: RENINetwork):
        super().__init__()
        self.network = network
        n = network.latents
        inputs = n * (n + 1) // 2 + 2 * n + 1
        layers = [Sine(inputs, network.width, FIRST_OMEGA, True)]
        layers += [Sine(network.width, network.width, 1.0, False) for _ in range(network.layers - 1)]
        self.body, self.out = nn.Sequential(*layers), nn.Linear(network.width, 3)

    def forward(self, z: torch.Tensor, d: torch.Tensor) -> torch.Tensor:
        """(B, N, 3) latents and (B, M, 3) unit directions -> (B, M, 3) values in the prior's encoding."""
        return self.out(self.body(invariants(z, d)))

    def decode(self, z: torch.Tensor, height: int) -> torch.Tensor:
        """Latents (B, N, 3) as (B, H, 2H, 3) maps in the prior's encoding."""
        d = map_directions(height, z.dtype, z.device)
        return self(z, d[None].expand(z.shape[0], -1, -1)).reshape(z.shape[0], height, 2 * height, 3)


def map_directions(height: int, dtype: torch.dtype = torch.float32, device: str | torch.device = "cpu") -> torch.Tensor:
    """The (H * 2H, 3) texel-centre directions of an H x 2H map, row by row."""
    return torch.from_numpy(texel_directions(height).reshape(-1, 3)).to(dtype=dtype, device=device)


def rotate_latent(z: torch.Tensor, degrees: float) -> torch.Tensor:
    """The latent (..., N, 3) turned by `degrees` about +Y (right-handed, as dpi.light.envmap.rotate_azimuth)."""
    a = math.radians(degrees)
    c, s = math.cos(a), math.sin(a)
    x, y, w = z[..., 0], z[..., 1], z[..., 2]
    return torch.stack([c * x + s * w, y, -s * x + c * w], dim=-1)


class RENI:
    """A trained decoder with what it was trained for: the family, the prior's encoding and the training maps' size."""

    def __init__(self, decoder: RENIDecoder, family: str, encoding: Encoding, height: int, latent_std: float):
        self.decoder, self.family, self.encoding, self.height = decoder, family, encoding, height
        self.latent_std = latent_std
        """the training latents' RMS: the prior over a map's latent is N(0, latent_std^2 I)"""

    def draw(self, count: int, generator: torch.Generator) -> torch.Tensor:
        """`count` latents (count, N, 3) drawn from the prior."""
        return self.latent_std * torch.randn((count, self.decoder.network.latents, 3), generator=generator)

    def log_radiance(self, z: torch.Tensor, height: int) -> torch.Tensor:
        """Latent (N, 3) -> the (H, 2H, 3) map's log radiance, at the training maps' median level: decoded at the
        training maps' size (the field holds no finer detail) and resampled across the sphere."""
        x = self.decoder.decode(z[None], self.height)[0].clamp(-1, 1)
        log_map = torch.log(self.encoding.to_radiance(x).clamp_min(1e-30)).permute(2, 0, 1)
        return resample_rows(log_map[None], height)[0].permute(1, 2, 0)


def load_reni(path: str | Path, family: str | None = None, encoding: Encoding | None = None,
              height: int | None = None) -> RENI:
    """A RENI checkpoint (the exported or the training one), refused with its file named when it is missing, of
    another format, or trained for another family, encoding or map size than given."""
    ckpt = read_checkpoint(path, FORMAT, "RENI", "train-reni", family, encoding, height)
    decoder = RENIDecoder(RENINetwork(**ckpt["network"]))
    decoder.load_state_dict({k: v.float() for k, v in ckpt["decoder"].items()})
    return RENI(decoder.eval().requires_grad_(False), ckpt["family"], encoding_from_dict(ckpt["encoding"]),
                ckpt["height"], float(ckpt["latent_std"]))


def train_reni(network: RENINetwork, cfg: RENITraining, maps: EnvmapDataset, out: str | Path,
               progress: bool = True) -> dict:
    """Fit the decoder and each map's latent Gaussian (module notes), checkpointing to `out` (resumed when it exists)
    until `cfg.steps` or `cfg.max_minutes`; a line of the log (`out`.log.jsonl) every LOG_EVERY steps. Returns the
    last line."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(cfg.seed)
    decoder = RENIDecoder(network)
    count, height = len(maps), maps.height
    mean = nn.Parameter(0.1 * torch.randn(count, network.latents, 3))
    log_std = nn.Parameter(torch.full((count, network.latents, 3), -3.0))
    optimizer = torch.optim.Adam([{"params": decoder.parameters(), "lr": cfg.lr},
                                  {"params": [mean, log_std], "lr": cfg.lr_latent}])
    step, wall = 0, 0.0
    if out.exists():
        ckpt = torch.load(out, map_location="cpu", weights_only=True)
        decoder.load_state_dict(ckpt["decoder"])
        with torch.no_grad():
            mean.copy_(ckpt["latent_mean"])
            log_std.copy_(ckpt["latent_log_std"])
        optimizer.load_state_dict(ckpt["optimizer"])
        step, wall = ckpt["step"], ckpt["wall_seconds"]
    directions = map_directions(height)
    area = torch.from_numpy(texel_solid_angles(height)[:, 0]).float().repeat_interleave(2 * height)
    targets = maps.images.permute(0, 2, 3, 1).reshape(count, -1, 3)
    generator = torch.Generator().manual_seed(cfg.seed * 1_000_003 + step)
    start = time.perf_counter() - wall
    deadline = None if cfg.max_minutes is None else time.perf_counter() + 60 * cfg.max_minutes
    record: dict = {"step": step}

    def save() -> None:
        save_atomic({"format": FORMAT, "family": maps.family, "encoding": maps.encoding.to_dict(), "height": height,
                     "median_target": median_target(maps.family, maps.encoding), "network": asdict(network),
                     "latent_std": float((mean.square() + (2 * log_std).exp()).mean().sqrt().detach()),
                     "train": asdict(cfg), "decoder": decoder.state_dict(), "latent_mean": mean.detach(),
                     "latent_log_std": log_std.detach(), "optimizer": optimizer.state_dict(), "step": step,
                     "wall_seconds": time.perf_counter() - start}, out)

    bar = tqdm(total=cfg.steps, initial=step, desc=f"train reni {maps.family}", disable=not progress)
    while step < cfg.steps and (deadline is None or time.perf_counter() < deadline):
        if maps.weights is None:
            idx = torch.randint(0, count, (cfg.batch_size,), generator=generator)
        else:
            idx = torch.multinomial(maps.weights, cfg.batch_size, replacement=True, generator=generator)
        pick = torch.multinomial(area, cfg.directions, replacement=True, generator=generator)
        std = log_std[idx].exp()
        z = mean[idx] + std * torch.randn(std.shape, generator=generator)
        predicted = decoder(z, directions[pick][None].expand(cfg.batch_size, -1, -1))
        error = (predicted - targets[idx][:, pick]).square().mean()
        kl = 0.5 * (mean[idx].square() + std.square() - 1.0 - 2.0 * log_std[idx]).mean()
        loss = error + cfg.kl_weight * kl
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        step += 1
        bar.update(1)
        if step % LOG_EVERY == 0:
            record = {"step": step, "seconds": round(time.perf_counter() - start, 2), "loss": round(loss.item(), 6),
                      "mse": round(error.item(), 6), "kl": round(kl.item(), 6)}
            bar.set_postfix(mse=f"{record['mse']:.4f}")
            with open(out.with_suffix(".log.jsonl"), "a") as log:
                log.write(json.dumps(record) + "\n")
        if step % CHECKPOINT_EVERY == 0:
            save()
    bar.close()
    save()
    return record


def export_reni(checkpoint: str | Path, dest: str | Path) -> None:
    """The shippable decoder and what it was trained for, without the training latents and the optimiser."""
    export_checkpoint(checkpoint, dest, ("latent_mean", "latent_log_std", "optimizer"))
