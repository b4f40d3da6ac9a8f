"""What the learned baselines (`reni`, `gan`) share: the training set they are fitted to, their checkpoints' checks
and export, and the shipped network a scene's family gets."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, TypeVar

import torch

from dpi.light.tonecurve import Encoding, family_encoding
from dpi.prior.data import EnvmapDataset, read_dataset
from dpi.prior.sample import DEFAULT_FAMILY, MODELS_DIR
from dpi.prior.train import save_atomic

N = TypeVar("N")


class CheckpointMismatch(ValueError):
    """A learned baseline's checkpoint of another format, encoding or training size than asked for."""


def training_set(family: str, height: int, data: str | Path, real: str | Path | None,
                 real_fraction: float) -> EnvmapDataset:
    """The procedural maps (a folder or a packed .npz) with the real panoramas' training split mixed in, as the
    diffusion priors train on them (dpi.prior.train), in the log encoding."""
    encoding = family_encoding(family, "log")
    maps = read_dataset(data, height, family, encoding)
    if real:
        maps = EnvmapDataset.mixed([maps, read_dataset(real, height, family, encoding)],
                                   [1.0 - real_fraction, real_fraction])
    return maps


def read_checkpoint(path: str | Path, fmt: str, what: str, command: str, family: str | None = None,
                    encoding: Encoding | None = None, height: int | None = None) -> dict[str, Any]:
    """A checkpoint of format `fmt` (a `what`, trained by `dpi command`), refused with its file named when it is
    missing, of another format, or trained for another family, encoding or map size than given."""
    if not Path(path).is_file():
        raise FileNotFoundError(f"{path}: no {what} checkpoint there; train one with `dpi {command}` (docs/priors.md) "
                                "or name yours in the method's `checkpoint` setting")
    ckpt = torch.load(path, map_location="cpu", weights_only=True)
    if not isinstance(ckpt, dict) or ckpt.get("format") != fmt:
        raise CheckpointMismatch(f"{path}: not a {what} checkpoint (format {fmt})")
    found = {"family": ckpt["family"], "encoding": ckpt["encoding"], "height": ckpt["height"]}
    asked = {"family": family, "encoding": None if encoding is None else encoding.to_dict(), "height": height}
    for key, value in asked.items():
        if value is not None and found[key] != value:
            raise CheckpointMismatch(f"{path}: trained for {key} {found[key]!r}, not {value!r}")
    return ckpt


def export_checkpoint(checkpoint: str | Path, dest: str | Path, drop: tuple[str, ...]) -> None:
    """The shippable copy of a training checkpoint: everything but the `drop` keys (training state)."""
    ckpt = torch.load(checkpoint, map_location="cpu", weights_only=True)
    save_atomic({k: v for k, v in ckpt.items() if k not in drop}, dest)


def shipped(kind: str) -> dict[str, Path]:
    """The shipped networks of a baseline (`reni`, `gan`) by family (their model card: dpi/data/models/README.md)."""
    return {family: MODELS_DIR / f"{kind}_{family}_32x64.pt" for family in ("outdoor", "indoor")}


def scene_network(options: dict, checkpoint: str | None, kind: str, load: Callable[..., N]) -> N:
    """The network of the scene's family (scene.yaml `prior`), or the configured `checkpoint`; `load` refuses one
    trained for another family."""
    family = options.get("prior", DEFAULT_FAMILY)
    return load(checkpoint or shipped(kind)[family], family=family)
