"""The few torchvision parts the Segment Anything packages import, for machines whose torchvision
cannot load (PyPI's torchvision is built against CUDA torch; these machines run the CPU build): `install` puts them
in sys.modules only when the real one fails to import. Resizing goes through PIL, as torchvision's does for a PIL
image, and torch's antialiased bilinear interpolation for a tensor."""

from __future__ import annotations

import sys
import types

import numpy as np
import torch
import torch.nn.functional as F


def to_pil_image(image):
    from PIL import Image

    return Image.fromarray(np.asarray(image))


def resize(image, size):
    from PIL import Image

    height, width = size
    return image.resize((width, height), Image.BILINEAR)


class ToTensor:
    def __call__(self, image) -> torch.Tensor:
        return torch.from_numpy(np.array(image, np.float32) / 255).permute(2, 0, 1).contiguous()


class Resize(torch.nn.Module):
    def __init__(self, size: tuple[int, int]):
        super().__init__()
        self.size = [int(size[0]), int(size[1])]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.interpolate(x[None], size=self.size, mode="bilinear", align_corners=False, antialias=True)[0]


class Normalize(torch.nn.Module):
    def __init__(self, mean: list[float], std: list[float]):
        super().__init__()
        self.mean = torch.tensor(mean)[:, None, None]
        self.std = torch.tensor(std)[:, None, None]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.mean) / self.std


def batched_nms(*args, **kwargs):  # and box_area: the automatic mask generator's, never the predictor's
    raise NotImplementedError("the stand-in has no box operations")


def install(monkeypatch) -> None:
    """The stand-in in sys.modules (through pytest's monkeypatch) when `import torchvision` fails."""
    try:
        import torchvision  # noqa: F401
        return
    except Exception:  # noqa: BLE001 - its ops fail to load against a CPU torch
        for name in [n for n in sys.modules if n == "torchvision" or n.startswith("torchvision.")]:
            monkeypatch.delitem(sys.modules, name)
    package = types.ModuleType("torchvision")
    transforms = types.ModuleType("torchvision.transforms")
    functional = types.ModuleType("torchvision.transforms.functional")
    ops, boxes = types.ModuleType("torchvision.ops"), types.ModuleType("torchvision.ops.boxes")
    functional.resize, functional.to_pil_image = resize, to_pil_image
    transforms.Normalize, transforms.Resize, transforms.ToTensor = Normalize, Resize, ToTensor
    boxes.batched_nms = boxes.box_area = batched_nms
    transforms.functional, package.transforms, ops.boxes, package.ops = functional, transforms, boxes, ops
    for module in (package, transforms, ops):
        module.__path__ = []
    for name, module in (("torchvision", package), ("torchvision.transforms", transforms),
                         ("torchvision.transforms.functional", functional), ("torchvision.ops", ops),
                         ("torchvision.ops.boxes", boxes)):
        monkeypatch.setitem(sys.modules, name, module)
