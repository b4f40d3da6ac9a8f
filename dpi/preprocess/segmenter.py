"""An optional learned segmenter that the user brings as an exported program: dpi never downloads weights.

The network is called once per view as `forward(image, prompt) -> logits`:
- image: (1, 3, H, W) float32 sRGB in [0, 1];
- prompt: (1, 1, H, W) float32, what the cameras already know (dpi.preprocess.masks.first_prior): 1 inside the
  core of the object's projected sparse points, 0.5 where the object probably is (the grown hull of those points
  and the sphere every camera sees), 0 elsewhere;
- logits: (1, 1, H, W), foreground where positive.
A salient-object network or a point-prompted model (Segment Anything with its prompt encoder folded in) wrapped to
that signature, exported with `torch.export.export` (H and W dynamic) and saved with `torch.export.save` (a .pt2
file) fits; `masks.weights` names the file, a relative name is looked up in $DPI_WEIGHTS.
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

import numpy as np
import torch

WEIGHTS_ENV = "DPI_WEIGHTS"
"""environment variable naming the folder where relative weight files are looked up"""
PROMPT_LEVELS = {1: 1.0, 3: 0.5}
"""prompt value of GrabCut's sure (GC_FGD) and probable (GC_PR_FGD) foreground labels; every other label is 0"""


def weights_file(weights: str) -> Path:
    """The segmenter's file: `weights` as given when absolute, else under $DPI_WEIGHTS (or the working folder);
    a missing file is one line naming the setting."""
    path = Path(weights).expanduser()
    if not path.is_absolute() and os.environ.get(WEIGHTS_ENV):
        path = Path(os.environ[WEIGHTS_ENV]).expanduser() / path
    if not path.is_file():
        raise ValueError(f"preprocess.masks.weights: {path} is not a file (a segmenter saved with torch.export.save; "
                         f"a relative name is looked up in ${WEIGHTS_ENV})")
    return path


@lru_cache(maxsize=2)
def load_segmenter(path: Path) -> torch.nn.Module:
    """The exported network in `path` as a module on the CPU (read once per process)."""
    import zipfile

    if not zipfile.is_zipfile(path):
        raise ValueError(f"{path}: not a segmenter saved with torch.export.save (not a .pt2 archive)")
    try:
        return torch.export.load(str(path)).module()
    except Exception as exc:  # noqa: BLE001 - any failure of a foreign file is one line naming it
        raise ValueError(f"{path}: not a segmenter saved with torch.export.save ({type(exc).__name__})") from None


def prompt_map(labels: np.ndarray) -> np.ndarray:
    """The prompt (h, w) float32 of GrabCut labels (h, w): PROMPT_LEVELS, 0 elsewhere."""
    prompt = np.zeros(labels.shape, np.float32)
    for label, level in PROMPT_LEVELS.items():
        prompt[labels == label] = level
    return prompt


def learned_mask(model: torch.nn.Module, image8: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Boolean foreground (h, w) the network finds in an 8-bit sRGB image (h, w, 3), prompted by GrabCut labels."""
    image = torch.from_numpy(np.ascontiguousarray(image8)).permute(2, 0, 1)[None].float() / 255
    prompt = torch.from_numpy(prompt_map(labels))[None, None]
    with torch.inference_mode():
        logits = model(image, prompt)
    if tuple(logits.shape) != (1, 1, *labels.shape):
        raise ValueError(f"the segmenter returned logits of shape {tuple(logits.shape)}; it must return "
                         f"(1, 1, {labels.shape[0]}, {labels.shape[1]}) for an image of that size")
    logits = logits[0, 0].float()
    if not torch.isfinite(logits).all():
        raise ValueError("the segmenter returned NaN or Inf logits")
    return (logits > 0).numpy()
