"""The learned segmenters a user brings, read from files on disk (dpi never downloads weights), each prompted per view
with what the cameras know (`Prompt`: dpi.preprocess.masks.view_prompt) and returning foreground logits.

`masks.segmenter` names the kind, `masks.weights` the file (a relative name is looked up in $DPI_WEIGHTS):
- **exported**: a program saved with `torch.export.save` (.pt2), called as `forward(image, prompt) -> logits` with
  image (1, 3, H, W) float32 sRGB in [0, 1], prompt (1, 1, H, W) float32 (`prompt_map`: 1 inside the core of the
  object's projected sparse points, 0.5 where the object probably is, 0 elsewhere), logits (1, 1, H, W);
- **sam**: a Segment Anything checkpoint (the `segment-anything` package; ViT-B, -L or -H, read from the
  checkpoint's widths), **sam2**: a SAM 2 or 2.1 checkpoint (the `sam2` package; Hiera tiny to large, read from its
  widths and depth): both built by the package's own builder, prompted with the object's projected points as positive
  points, the background's as negative ones and the box of where the object probably is;
- **rembg**: a salient-object ONNX model such as rembg's (u2net, isnet, ...), run through `onnxruntime` on the crop
  of that box (grown by `CROP_MARGIN`), normalised as rembg normalises its input.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Protocol

import numpy as np
import torch

WEIGHTS_ENV = "DPI_WEIGHTS"
"""environment variable naming the folder where relative weight files are looked up"""
KINDS = ("exported", "sam", "sam2", "rembg")
"""the segmenters `masks.segmenter` names"""
PROMPT_LEVELS = {1: 1.0, 3: 0.5}
"""prompt value of GrabCut's sure (GC_FGD) and probable (GC_PR_FGD) foreground labels; every other label is 0"""
CROP_MARGIN = 0.1
"""the salient-object crop: the box of where the object probably is, grown by this fraction of its size a side"""
IMAGENET_MEAN, IMAGENET_STD = (0.485, 0.456, 0.406), (0.229, 0.224, 0.225)
"""rembg's input normalisation (after dividing the image by its maximum)"""
SAM_WIDTHS = {768: "vit_b", 1024: "vit_l", 1280: "vit_h"}
"""Segment Anything's image encoders by the width of their patch embedding"""
SAM2_SIZES = {(96, 12): "t", (96, 16): "s", (112, 24): "b+", (144, 48): "l"}
"""SAM 2's Hiera trunks by (width of the patch embedding, blocks)"""
INSTALL = {"sam": "pip install segment-anything", "sam2": "SAM2_BUILD_CUDA=0 pip install sam2",
           "rembg": "pip install onnxruntime"}
"""how to get each kind's package"""


@dataclass(frozen=True)
class Prompt:
    """What the cameras know about one view: GrabCut's first labels (h, w), pixel positions (x right, y down; N, 2)
    of the object's and the background's projected sparse points, and the box (x0, y0, x1, y1) of where the object
    probably is."""

    labels: np.ndarray
    positive: np.ndarray
    negative: np.ndarray
    box: np.ndarray


class Segmenter(Protocol):
    def logits(self, image8: np.ndarray, prompt: Prompt) -> np.ndarray:
        """Foreground logits (h, w) float32 of an 8-bit sRGB image (h, w, 3): foreground where positive."""


def weights_file(weights: str) -> Path:
    """The segmenter's file: `weights` as given when absolute, else under $DPI_WEIGHTS (or the working folder);
    a missing file is one line naming the setting."""
    path = Path(weights).expanduser()
    if not path.is_absolute() and os.environ.get(WEIGHTS_ENV):
        path = Path(os.environ[WEIGHTS_ENV]).expanduser() / path
    if not path.is_file():
        raise ValueError(f"preprocess.masks.weights: {path} is not a file (the segmenter's weights; a relative name "
                         f"is looked up in ${WEIGHTS_ENV})")
    return path


def prompt_map(labels: np.ndarray) -> np.ndarray:
    """The prompt (h, w) float32 of GrabCut labels (h, w): PROMPT_LEVELS, 0 elsewhere."""
    prompt = np.zeros(labels.shape, np.float32)
    for label, level in PROMPT_LEVELS.items():
        prompt[labels == label] = level
    return prompt


def checked_logits(logits, shape: tuple[int, int], kind: str) -> np.ndarray:
    """The segmenter's logits as (h, w) float32, or one line saying what is wrong with them."""
    logits = np.asarray(logits, np.float32)
    if logits.shape != shape:
        raise ValueError(f"the {kind} segmenter returned logits of shape {logits.shape}; an image of {shape[1]} x "
                         f"{shape[0]} needs ({shape[0]}, {shape[1]})")
    if not np.isfinite(logits).all():
        raise ValueError(f"the {kind} segmenter returned NaN or Inf logits")
    return logits


def learned_mask(segmenter: Segmenter, image8: np.ndarray, prompt: Prompt) -> np.ndarray:
    """Boolean foreground (h, w) the segmenter finds in an 8-bit sRGB image (h, w, 3) under the view's prompt."""
    return checked_logits(segmenter.logits(image8, prompt), image8.shape[:2], type(segmenter).__name__) > 0


class Exported:
    """A program saved with torch.export.save, called on the image and the prompt map."""

    def __init__(self, module: torch.nn.Module):
        self.module = module

    def logits(self, image8: np.ndarray, prompt: Prompt) -> np.ndarray:
        image = torch.from_numpy(np.ascontiguousarray(image8)).permute(2, 0, 1)[None].float() / 255
        with torch.inference_mode():
            out = self.module(image, torch.from_numpy(prompt_map(prompt.labels))[None, None])
        if tuple(out.shape) != (1, 1, *image8.shape[:2]):
            raise ValueError(f"the segmenter returned logits of shape {tuple(out.shape)}; it must return "
                             f"(1, 1, {image8.shape[0]}, {image8.shape[1]}) for an image of that size")
        return out[0, 0].float().numpy()


class PointPrompted:
    """Segment Anything (1 or 2) behind its package's image predictor: points and box in, the best mask's logits out."""

    def __init__(self, predictor):
        self.predictor = predictor

    def logits(self, image8: np.ndarray, prompt: Prompt) -> np.ndarray:
        coords = np.concatenate([prompt.positive, prompt.negative]).astype(np.float32)
        labels = np.concatenate([np.ones(len(prompt.positive)), np.zeros(len(prompt.negative))]).astype(np.int64)
        with torch.inference_mode():
            self.predictor.set_image(np.ascontiguousarray(image8))
            masks, scores, _ = self.predictor.predict(point_coords=coords if len(coords) else None,
                                                      point_labels=labels if len(coords) else None,
                                                      box=prompt.box.astype(np.float32), multimask_output=False,
                                                      return_logits=True)
        return np.asarray(masks[int(np.argmax(scores))], np.float32)


class SalientObject:
    """A salient-object ONNX model (rembg's) on the crop of where the object probably is; background outside it."""

    def __init__(self, session):
        self.session = session
        self.input = session.get_inputs()[0]

    def logits(self, image8: np.ndarray, prompt: Prompt) -> np.ndarray:
        import cv2

        h, w = image8.shape[:2]
        x0, y0, x1, y1 = prompt.box
        grow_x, grow_y = CROP_MARGIN * (x1 - x0), CROP_MARGIN * (y1 - y0)
        c0, c1 = int(max(np.floor(x0 - grow_x), 0)), int(min(np.ceil(x1 + grow_x), w))
        r0, r1 = int(max(np.floor(y0 - grow_y), 0)), int(min(np.ceil(y1 + grow_y), h))
        crop = image8[r0:r1, c0:c1]
        size = [s if isinstance(s, int) else None for s in self.input.shape[2:]]
        in_h, in_w = size[0] or crop.shape[0], size[1] or crop.shape[1]
        x = cv2.resize(crop, (in_w, in_h), interpolation=cv2.INTER_LANCZOS4).astype(np.float32)
        x = (x / max(float(x.max()), 1e-6) - IMAGENET_MEAN) / IMAGENET_STD
        out = self.session.run(None, {self.input.name: x.transpose(2, 0, 1)[None].astype(np.float32)})[0]
        pred = np.asarray(out, np.float32).reshape(out.shape[-2:])
        if pred.min() >= 0 and pred.max() <= 1:  # probabilities (u2net, isnet); logits otherwise (birefnet)
            pred = pred - 0.5
        logits = np.full((h, w), -1.0, np.float32)
        logits[r0:r1, c0:c1] = cv2.resize(pred, (c1 - c0, r1 - r0), interpolation=cv2.INTER_LINEAR)
        return logits


def need(kind: str, module: str):
    """The kind's package, or one line saying which to install."""
    import importlib

    package = module.split(".")[0]
    try:
        return importlib.import_module(module)
    except ImportError:
        raise ValueError(f"preprocess.masks.segmenter {kind} needs the {package} package: {INSTALL[kind]}") from None
    except Exception as exc:  # noqa: BLE001 - e.g. a torchvision built for another torch
        raise ValueError(f"preprocess.masks.segmenter {kind}: the {package} package does not import here "
                         f"({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})") from None


def state_dict(path: Path, kind: str, key: str | None = None) -> dict:
    """The tensors of a PyTorch checkpoint (under `key` when given), or one line naming the file."""
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
        return state[key] if key else state
    except Exception as exc:  # noqa: BLE001 - any failure of a foreign file is one line naming it
        raise ValueError(f"{path}: not a {kind} checkpoint ({type(exc).__name__})") from None


def sam_variant(state: dict) -> str:
    """Segment Anything's registry name of a checkpoint's image encoder (vit_b / vit_l / vit_h)."""
    weight = state.get("image_encoder.patch_embed.proj.weight")
    if weight is None or int(weight.shape[0]) not in SAM_WIDTHS:
        raise ValueError("not a Segment Anything image encoder (no ViT-B/L/H patch embedding)")
    return SAM_WIDTHS[int(weight.shape[0])]


def sam2_config(state: dict) -> str:
    """The `sam2` package's config of a checkpoint: its Hiera size, from the trunk's width and blocks, and its version
    (2.1 checkpoints carry `no_obj_embed_spatial`)."""
    weight = state.get("image_encoder.trunk.patch_embed.proj.weight")
    blocks = len({k.split(".")[3] for k in state if k.startswith("image_encoder.trunk.blocks.")})
    size = None if weight is None else SAM2_SIZES.get((int(weight.shape[0]), blocks))
    if size is None:
        raise ValueError("not a SAM 2 checkpoint (no Hiera trunk of a known size)")
    version = "sam2.1" if "no_obj_embed_spatial" in state else "sam2"
    return f"configs/{version}/{version}_hiera_{size}.yaml"


def build_sam(state: dict):
    """A Segment Anything image predictor holding `state`."""
    sam = need("sam", "segment_anything")
    model = sam.sam_model_registry[sam_variant(state)]()
    model.load_state_dict(state)
    return PointPrompted(sam.SamPredictor(model.eval()))


def build_sam2(state: dict):
    """A SAM 2 image predictor holding `state`."""
    builder = need("sam2", "sam2.build_sam")
    predictor = need("sam2", "sam2.sam2_image_predictor")
    model = builder.build_sam2(sam2_config(state), None, device="cpu")
    model.load_state_dict(state)
    return PointPrompted(predictor.SAM2ImagePredictor(model.eval()))


@lru_cache(maxsize=2)
def load_segmenter(kind: str, path: Path) -> Segmenter:
    """The segmenter of `kind` held in `path`, on the CPU (read once per process); a file of another kind, or a
    missing package, is one line."""
    if kind not in KINDS:
        raise ValueError(f"preprocess.masks.segmenter must be one of {', '.join(KINDS)}, got {kind!r}")
    if kind == "exported":
        import zipfile

        if not zipfile.is_zipfile(path):
            raise ValueError(f"{path}: not a segmenter saved with torch.export.save (not a .pt2 archive)")
        try:
            return Exported(torch.export.load(str(path)).module())
        except Exception as exc:  # noqa: BLE001 - any failure of a foreign file is one line naming it
            raise ValueError(f"{path}: not a segmenter saved with torch.export.save ({type(exc).__name__})") from None
    if kind == "rembg":
        ort = need(kind, "onnxruntime")
        try:
            return SalientObject(ort.InferenceSession(str(path), providers=["CPUExecutionProvider"]))
        except Exception as exc:  # noqa: BLE001
            raise ValueError(f"{path}: not an ONNX model ({type(exc).__name__})") from None
    need(kind, "segment_anything" if kind == "sam" else "sam2.sam2_image_predictor")
    build, key = (build_sam, None) if kind == "sam" else (build_sam2, "model")
    state = state_dict(path, kind, key)
    try:
        return build(state)
    except (RuntimeError, ValueError) as exc:
        raise ValueError(f"{path}: {str(exc).splitlines()[0]}") from None
