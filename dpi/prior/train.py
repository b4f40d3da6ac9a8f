"""Training a diffusion prior on a folder of env maps: Adam, EMA, resumable atomic checkpoints, logs.

A checkpoint is a dict: 'format', 'config' (UNetConfig), 'family', 'height', 'tone' (the encoding's
parameters, dpi.light.tonecurve, and median_target), 'diffusion' (num_timesteps, schedule), 'model', 'ema',
'optimizer', 'step', 'wall_seconds', 'train' (TrainConfig). `export_model` strips it to EMA weights
(fp16) for shipping. Next to the checkpoint go `{stem}.log.jsonl` (one line per logged step) and
`{stem}_samples/`. On a GPU the maps live on the device and the forward pass runs in bfloat16
autocast, so a step is bound by the network, not by host-device copies.
"""

from __future__ import annotations

import copy
import json
import math
import time
from dataclasses import asdict, field, fields, replace
from pathlib import Path

import torch
from tqdm import tqdm

from dpi.io.atomic import atomic_path
from dpi.io.settings import Count, Fraction, MapHeight, Rate, SettingsError, Steps, settings, settings_from_dict
from dpi.light.tonecurve import family_encoding
from dpi.prior.data import EnvmapDataset, clip_highlights, median_target, read_dataset
from dpi.prior.diffusion import base_diffusion, evenly_spaced_timesteps, respaced, sample, training_losses
from dpi.prior.sample import write_grid
from dpi.prior.unet import SMALL_CONFIGS, CheckpointError, UNetModel, count_parameters, load_checkpoint

CHECKPOINT_FORMAT = "dpi-prior-v1"
LR_SCHEDULES = ("constant", "cosine")
"""learning-rate schedules after the warm-up (`learning_rate`)"""
DEFAULT_MODEL = "small_32x64"
"""the network (a name in dpi.prior.unet.SMALL_CONFIGS) a prior is trained with unless told otherwise"""


CLIP_MULTIPLES = (3.0, 30.0)  # clip levels, in multiples of the median luminance


DIFFUSION_STEPS = 1000
"""timesteps of the linear noise schedule every prior is trained on (the paper's)"""
SAMPLE_GRID_STEPS = 50
"""respaced reverse steps of the sample grids a run writes"""
LOG_EVERY = 10
"""optimiser steps between two lines of the training log"""
CHECKPOINT_EVERY = 100
"""optimiser steps between two saves of the resumable checkpoint"""


def training_device() -> str:
    """Where a prior trains: the GPU when torch sees one (CUDA_VISIBLE_DEVICES= keeps it on the CPU)."""
    return "cuda" if torch.cuda.is_available() else "cpu"


@settings
class TrainConfig:
    """How a prior is trained (what on and where to: `train`'s arguments)."""

    model: str = DEFAULT_MODEL  # the network, a name in dpi.prior.unet.SMALL_CONFIGS
    steps: Count = 20000  # total optimiser steps (including resumed ones)
    batch_size: Count = 8
    lr: Rate = 3e-4
    warmup_steps: Steps = 0  # linear learning-rate warm-up from 0 (large batches on a GPU want a few hundred)
    lr_schedule: str = "constant"  # 'constant', or 'cosine' (decays to 0 at `steps`; a fine-tune's end)
    init: str | None = None  # start a new run from this prior's weights (model and EMA), which may be of another map
    # size with the same network (a 32 x 64 prior starting a 64 x 128 run); ignored when resuming
    ema_decay: Fraction = 0.995  # with warm-up min(decay, (1 + step) / (10 + step)); short CPU runs want < 0.999
    max_minutes: Rate | None = None  # stop after this wall time (checkpoint written)
    sample_every: Steps = 1000  # write a PNG grid of EMA samples every N steps (0: never)
    seed: int = 0
    encoding: str = "log"  # 'log' (log radiance around the median) or 'paper' (the family's tone curve)
    clip_fraction: Fraction = 0.0  # share of each batch clipped like 8-bit panoramas (dpi.prior.data.clip_highlights)
    real_data: str | None = None  # real panoramas (a folder or a set packed by `dpi panorama-set`) mixed in
    real_fraction: Fraction = 0.25  # share of each batch drawn from `real_data`

    def __post_init__(self):
        """An unknown network or schedule fails here, not at the first optimiser step."""
        if self.model not in SMALL_CONFIGS:
            raise SettingsError("model", f"unknown network {self.model!r}; choose from "
                                         f"{', '.join(sorted(SMALL_CONFIGS))}")
        if self.lr_schedule not in LR_SCHEDULES:
            raise SettingsError("lr_schedule", f"unknown schedule {self.lr_schedule!r}; choose from "
                                               f"{', '.join(LR_SCHEDULES)}")


@settings
class PriorJobConfig:
    """How the workflow makes one family's prior (config `prior:`, then `prior.<family>`): a procedural
    dataset (rule envmap_dataset), then a training run (rule train_prior). Keys other than these fields are
    TrainConfig fields (model, seed: also the dataset's, steps, batch_size, lr, ema_decay, max_minutes, ...)."""

    count: Count = 3000
    """maps in the procedural dataset"""
    data_height: MapHeight = 64
    """their height H (maps are H x 2H; indoor ray casting costs ~H^2)"""
    threads: Count = 1
    """CPU threads of the training job"""
    train: dict = field(default_factory=dict)
    """the TrainConfig fields set"""

    @classmethod
    def from_dict(cls, values: dict) -> "PriorJobConfig":
        """Settings from a family's merged `prior` section; unknown keys and bad values are errors."""
        own = {f.name for f in fields(cls)} - {"train"}
        job = settings_from_dict(cls, {k: v for k, v in values.items() if k in own})
        job.train = {k: v for k, v in values.items() if k not in own}
        job.train_config()  # checks the training keys
        return job

    def train_config(self) -> "TrainConfig":
        """The training run's settings."""
        return settings_from_dict(TrainConfig, self.train)


def learning_rate(cfg: TrainConfig, step: int) -> float:
    """The learning rate of optimiser step `step` (0-based): linear warm-up, then constant or cosine to 0."""
    rate = cfg.lr * min(1.0, (step + 1) / cfg.warmup_steps) if cfg.warmup_steps else cfg.lr
    if cfg.lr_schedule == "cosine":
        rate *= 0.5 * (1.0 + math.cos(math.pi * min(step, cfg.steps) / cfg.steps))
    return rate


def ema_update(ema: torch.nn.Module, model: torch.nn.Module, decay: float) -> None:
    """ema <- decay ema + (1 - decay) model, parameter by parameter."""
    with torch.no_grad():
        torch._foreach_lerp_(list(ema.parameters()), list(model.parameters()), 1.0 - decay)


def checkpoint_dict(cfg: TrainConfig, family: str, model: UNetModel, ema: UNetModel,
                    optimizer: torch.optim.Optimizer, step: int, wall_seconds: float) -> dict:
    """The resumable checkpoint of a run."""
    encoding = family_encoding(family, cfg.encoding)
    network = SMALL_CONFIGS[cfg.model]
    return {
        "format": CHECKPOINT_FORMAT, "config": network.to_dict(), "family": family,
        "height": network.image_size,
        "tone": {**encoding.to_dict(), "median_target": median_target(family, encoding)},
        "diffusion": {"num_timesteps": DIFFUSION_STEPS, "schedule": "linear"},
        "model": model.state_dict(), "ema": ema.state_dict(), "optimizer": optimizer.state_dict(),
        "step": step, "wall_seconds": wall_seconds,
        "train": asdict(cfg),
    }


def save_atomic(obj: dict, path: str | Path) -> None:
    """torch.save to a temporary sibling, then rename (a killed run never leaves half a file)."""
    with atomic_path(path) as tmp:
        torch.save(obj, tmp)


def export_model(checkpoint: str | Path, dest: str | Path, half: bool = True) -> None:
    """Shippable copy of a checkpoint: EMA weights (fp16 if `half`) and metadata, no optimiser."""
    ckpt = torch.load(checkpoint, map_location="cpu", weights_only=True)
    weights = {k: v.half() if half and v.is_floating_point() else v for k, v in ckpt["ema"].items()}
    keep = {k: v for k, v in ckpt.items() if k not in ("model", "ema", "optimizer")}
    save_atomic({**keep, "model": weights, "ema": None}, dest)


def write_sample_grid(cfg: TrainConfig, ema: UNetModel, step: int, out_dir: Path) -> None:
    """PNG grid of 8 EMA samples (respaced schedule, random roll) at this step."""
    diffusion = respaced(base_diffusion(DIFFUSION_STEPS),
                         evenly_spaced_timesteps(DIFFUSION_STEPS, SAMPLE_GRID_STEPS))
    h, device = ema.config.image_size, next(ema.parameters()).device
    generator = torch.Generator(device=device).manual_seed(cfg.seed)
    x = sample(diffusion, ema, (8, 3, h, 2 * h), generator, random_roll=True, device=device)
    write_grid(out_dir / f"step_{step:06d}.png", x)


def train(cfg: TrainConfig, family: str, data_dir: str | Path, out: str | Path, dataset: EnvmapDataset | None = None,
          progress: bool = True) -> dict:
    """Train a `family` prior on `data_dir` (a folder of panoramas or a packed .npz; or `dataset`), checkpointing to
    `out` (resumed when it exists), until `cfg.steps` or `cfg.max_minutes`; returns the last log line."""
    out, network = Path(out), SMALL_CONFIGS[cfg.model]
    log_path = out.with_suffix(".log.jsonl")
    samples_dir = out.parent / f"{out.stem}_samples"
    out.parent.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(cfg.seed)
    device = training_device()
    encoding = family_encoding(family, cfg.encoding)
    data = dataset or read_dataset(data_dir, network.image_size, family, encoding)
    if cfg.real_data:
        real = read_dataset(cfg.real_data, network.image_size, family, encoding)
        data = EnvmapDataset.mixed([data, real], [1.0 - cfg.real_fraction, cfg.real_fraction])
    data = data.to(device)
    model = UNetModel(network).to(device)
    ema = copy.deepcopy(model).eval().requires_grad_(False)
    cuda = torch.device(device).type == "cuda"
    optimizer = torch.optim.Adam(model.parameters(), lr=cfg.lr, fused=cuda or None)
    step, wall = 0, 0.0
    if out.exists():
        ckpt = torch.load(out, map_location=device, weights_only=True)
        model.load_state_dict(ckpt["model"])
        ema.load_state_dict(ckpt["ema"])
        optimizer.load_state_dict(ckpt["optimizer"])
        step, wall = ckpt["step"], ckpt["wall_seconds"]
    elif cfg.init:
        initial = load_checkpoint(cfg.init, device=device).float()
        if replace(initial.config, image_size=network.image_size) != network:
            raise CheckpointError(f"{cfg.init}: its network differs from the run's model; train with the same network "
                                  "(a model of another map size with the same weights will do)")
        model.load_state_dict(initial.state_dict())
        ema.load_state_dict(initial.state_dict())
    diffusion = base_diffusion(DIFFUSION_STEPS)
    generator = torch.Generator(device=device).manual_seed(cfg.seed * 1_000_003 + step)
    start = time.perf_counter() - wall
    deadline = None if cfg.max_minutes is None else time.perf_counter() + 60 * cfg.max_minutes
    record: dict = {"step": step}
    bar = tqdm(total=cfg.steps, initial=step, desc=f"train {family}", disable=not progress,
               postfix={"params": f"{count_parameters(model) / 1e6:.2f}M"})
    while step < cfg.steps and (deadline is None or time.perf_counter() < deadline):
        x0 = data.batch(cfg.batch_size, generator)
        if cfg.clip_fraction:
            x0 = clip_highlights(x0, data.encoding, median_target(family, data.encoding), cfg.clip_fraction,
                                 CLIP_MULTIPLES, generator)
        t = torch.randint(0, DIFFUSION_STEPS, (cfg.batch_size,), generator=generator, device=device)
        noise = torch.randn(x0.shape, generator=generator, device=device)
        with torch.autocast("cuda", dtype=torch.bfloat16, enabled=cuda):
            losses = {k: v.mean() for k, v in training_losses(diffusion, model, x0, t, noise).items()}
        losses_logged = {k: v.detach() for k, v in losses.items()}
        optimizer.zero_grad(set_to_none=True)
        losses["loss"].backward()
        for group in optimizer.param_groups:
            group["lr"] = learning_rate(cfg, step)
        optimizer.step()
        step += 1
        ema_update(ema, model, min(cfg.ema_decay, (1 + step) / (10 + step)))
        bar.update(1)
        if step % LOG_EVERY == 0:
            record = {"step": step, "seconds": round(time.perf_counter() - start, 2),
                      **{k: round(v.item(), 6) for k, v in losses_logged.items()}}
            bar.set_postfix(loss=f"{record['loss']:.4f}")
            with open(log_path, "a") as log:
                log.write(json.dumps(record) + "\n")
        if step % CHECKPOINT_EVERY == 0 or step == cfg.steps:
            save_atomic(checkpoint_dict(cfg, family, model, ema, optimizer, step, time.perf_counter() - start), out)
        if cfg.sample_every and step % cfg.sample_every == 0:
            write_sample_grid(cfg, ema, step, samples_dir)
    bar.close()
    save_atomic(checkpoint_dict(cfg, family, model, ema, optimizer, step, time.perf_counter() - start), out)
    return record


def train_and_export(cfg: TrainConfig, family: str, data_dir: str | Path, out: str | Path, dest: str | Path) -> dict:
    """Train (resuming from the working checkpoint `out`) and export the EMA model to `dest`."""
    record = train(cfg, family, data_dir, out)
    export_model(out, dest)
    return record
