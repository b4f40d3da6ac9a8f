"""Learned perceptual metrics with their published networks: LPIPS (Zhang et al. 2018; AlexNet
backbone, package `lpips`) and FID (Heusel et al. 2017; the TensorFlow FID Inception of package
`pytorch-fid`).

Backbone weights are never downloaded: they are read from a local folder, $DPI_WEIGHTS, else
torch's hub checkpoint folder (`torch.hub.get_dir()/checkpoints`, where torchvision and
pytorch-fid would cache them), under the names those packages give them (`ALEXNET_WEIGHTS`,
`INCEPTION_WEIGHTS`). `missing_weights` says, before anything is built, which file is absent
from which folder; callers record that as the metric's missing reason. LPIPS's linear layers
ship inside the `lpips` package.

Inputs are display images (H, W, 3) in [0, 1]. The Fréchet distance is computed here from
the features' singular values (exact for the rank-deficient covariances of small sets).
"""

from __future__ import annotations

import os
import sys
import types
import warnings
from functools import cache
from pathlib import Path
from unittest import mock

import numpy as np
import torch
from torch import nn

from dpi.evaluation.metrics import resize_image

WEIGHTS_ENV = "DPI_WEIGHTS"
ALEXNET_WEIGHTS = "alexnet-owt-7be5be79.pth"
"""torchvision's ImageNet AlexNet (AlexNet_Weights.IMAGENET1K_V1), LPIPS's backbone"""
INCEPTION_WEIGHTS = "pt_inception-2015-12-05-6726825d.pth"
"""pytorch-fid's port of the TensorFlow FID Inception weights"""
LPIPS_MIN_SIZE = 64
"""images are upsampled (bilinear) until their shorter side is at least this (AlexNet needs > 32 px)"""
FID_ROLLS = 4
"""each env map enters FID as this many azimuth rotations (multiples of 360 / FID_ROLLS degrees)"""


def weights_dir() -> Path:
    """The folder backbone weights are read from: $DPI_WEIGHTS, else torch.hub.get_dir()/checkpoints."""
    return Path(os.environ.get(WEIGHTS_ENV) or Path(torch.hub.get_dir()) / "checkpoints")


def missing_weights(name: str) -> str | None:
    """Why a weights file cannot be used (it is absent), or None when it is there."""
    folder = weights_dir()
    if (folder / name).is_file():
        return None
    return f"no {name} in {folder} (set {WEIGHTS_ENV} to a folder holding it)"


def import_torchvision() -> types.ModuleType:
    """torchvision, also where its C++ detection ops cannot load (PyPI's CUDA wheel beside a CPU torch).

    Its `_meta_registrations` module then fails at import ("operator torchvision::nms does not
    exist"); the networks used here are plain PyTorch modules that need none of those ops, so
    that module is skipped."""
    try:
        import torchvision
    except RuntimeError as exc:
        if "torchvision::" not in str(exc):
            raise
        for name in [n for n in sys.modules if n == "torchvision" or n.startswith("torchvision.")]:
            del sys.modules[name]
        sys.modules["torchvision._meta_registrations"] = types.ModuleType("torchvision._meta_registrations")
        import torchvision
    return torchvision


def lpips_network(backbone: Path | None) -> nn.Module:
    """LPIPS v0.1 (AlexNet) with its packaged linear layers; backbone from a torchvision AlexNet
    checkpoint (its `features.*` tensors), or left randomly initialised when None."""
    import_torchvision()
    import lpips

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # torchvision's notice on lpips' `pretrained=False`
        net = lpips.LPIPS(net="alex", version="0.1", pnet_rand=True, verbose=False)
    if backbone is not None:
        features = torch.load(backbone, map_location="cpu", weights_only=True)
        # lpips keeps AlexNet's feature layers in slices, under their index in `features`
        net.net.load_state_dict({k: features[f"features.{k.split('.', 1)[1]}"] for k in net.net.state_dict()})
    return net.eval()


@cache
def pretrained_lpips() -> nn.Module:
    """LPIPS with the AlexNet backbone from the weights folder (check `missing_weights` first)."""
    return lpips_network(weights_dir() / ALEXNET_WEIGHTS)


def lpips_distance(a: np.ndarray, b: np.ndarray, net: nn.Module) -> float:
    """LPIPS between two display images (H, W, 3) in [0, 1], upsampled to LPIPS_MIN_SIZE if smaller."""
    h, w = a.shape[:2]
    f = max(1.0, LPIPS_MIN_SIZE / min(h, w))
    size = (round(h * f), round(w * f))
    x = torch.from_numpy(np.stack([resize_image(a, *size), resize_image(b, *size)])).permute(0, 3, 1, 2).float()
    with torch.no_grad():
        return float(net(x[:1], x[1:], normalize=True))


def inception_network(weights: Path) -> nn.Module:
    """pytorch-fid's FID InceptionV3 (2048-d pool features) with its weights read from `weights`."""
    import_torchvision()
    from pytorch_fid import inception

    def load_local(url: str, **kwargs) -> dict:  # pytorch-fid fetches by URL inside its constructor
        return torch.load(weights, map_location="cpu", weights_only=True)

    with mock.patch.object(inception, "load_state_dict_from_url", load_local):
        return inception.InceptionV3([inception.InceptionV3.BLOCK_INDEX_BY_DIM[2048]]).eval()


@cache
def pretrained_inception() -> nn.Module:
    """The FID Inception from the weights folder (check `missing_weights` first)."""
    return inception_network(weights_dir() / INCEPTION_WEIGHTS)


def inception_features(images: list[np.ndarray], net: nn.Module, batch: int = 16) -> np.ndarray:
    """Pool features (N, 2048) of display images (H, W, 3) in [0, 1]; the network resizes them to 299."""
    x = torch.from_numpy(np.stack(images).astype(np.float32)).permute(0, 3, 1, 2)
    with torch.no_grad():
        return torch.cat([net(chunk)[0].flatten(1) for chunk in x.split(batch)]).double().numpy()


def azimuth_rolls(env: np.ndarray, count: int = FID_ROLLS) -> list[np.ndarray]:
    """An equirectangular map (H, W, C) rotated about the up axis by multiples of 360 / count degrees."""
    return [np.roll(env, k * env.shape[1] // count, axis=1) for k in range(count)]


def frechet_distance(f1: np.ndarray, f2: np.ndarray) -> float:
    """Fréchet distance between Gaussians fitted to two feature sets (N1, D) and (N2, D), N >= 2:
    ||mu1 - mu2||^2 + tr S1 + tr S2 - 2 tr (S1 S2)^1/2.

    With S = A^T A (A: the centred features / sqrt(N - 1)), the eigenvalues of S1 S2 are the squared
    singular values of A1 A2^T, so tr (S1 S2)^1/2 is its nuclear norm: exact, and nothing D x D is formed."""
    a1 = (f1 - f1.mean(0)) / np.sqrt(len(f1) - 1)
    a2 = (f2 - f2.mean(0)) / np.sqrt(len(f2) - 1)
    d = f1.mean(0) - f2.mean(0)
    cross = np.linalg.svd(a1 @ a2.T, compute_uv=False).sum()
    return max(float(d @ d + (a1**2).sum() + (a2**2).sum() - 2 * cross), 0.0)
