"""Building small capture folders for tests: a valid one, and edits that break one part of it."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Callable

import numpy as np
import OpenEXR
import trimesh

from dpi.capture.cameras import Camera, from_fov, orbit, write_transforms
from dpi.io.exr import write_exr
from dpi.io.images import write_mask, write_srgb

NAMES = ("r_0", "r_1", "r_2", "r_3")
FRAME_PATHS = ("images/r_0.png", "./images/r_1", "r_2", "images/r_3.exr")
SIZE = 8
DISTANCE, FOV_DEG = 3.0, 40.0


def image(value: float = 0.5, height: int = SIZE, width: int = SIZE) -> np.ndarray:
    """A small smooth linear RGB test image."""
    ramp = np.linspace(0.1, 1.0, width, dtype=np.float32)
    return value * np.broadcast_to(ramp[None, :, None], (height, width, 3)).copy()


def raw_exr(path: Path, data: np.ndarray) -> None:
    """Write an RGB EXR without dpi's NaN/Inf guard, to build broken inputs."""
    channels = {c: np.ascontiguousarray(data[..., i].astype(np.float32)) for i, c in enumerate("RGB")}
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, channels) as exr:
        exr.write(str(path))


def cameras(n: int = len(NAMES)) -> list[Camera]:
    """Cameras on a ring around the origin, 8x8 pixels."""
    return [from_fov(c2w, SIZE, SIZE, FOV_DEG) for c2w in orbit(n, DISTANCE, (20.0, 35.0))]


def sphere_mask() -> np.ndarray:
    """What every camera of `cameras` sees of the unit sphere at the origin (the capture's mesh): the disc
    of pixel centres within its projected radius f tan(asin(1 / distance))."""
    focal = SIZE / (2 * math.tan(math.radians(FOV_DEG) / 2))
    radius = focal * math.tan(math.asin(1 / DISTANCE))
    y, x = np.mgrid[:SIZE, :SIZE] + 0.5
    return np.hypot(x - SIZE / 2, y - SIZE / 2) <= radius


def make_capture(root: Path, transforms: bool = True, masks: bool = True, mesh: bool = True,
                 gt: bool = True) -> Path:
    """A valid tiny capture: r_0, r_1 as PNG, r_2, r_3 as EXR, r_3 flagged held out."""
    (root / "images").mkdir(parents=True)
    for i, name in enumerate(NAMES):
        if i < 2:
            write_srgb(root / "images" / f"{name}.png", image(0.2 + 0.1 * i))
        else:
            write_exr(root / "images" / f"{name}.exr", image(2.0 + i))
    if transforms:
        cams = cameras()
        cams[3].extras["held_out"] = True
        (root / "transforms.json").write_text(json.dumps(write_transforms(list(zip(FRAME_PATHS, cams)))))
    if masks:
        for name in NAMES:
            write_mask(root / "masks" / f"{name}.png", sphere_mask())
    if mesh:
        trimesh.creation.icosphere(subdivisions=1).export(root / "mesh.ply")
    if gt:
        (root / "gt").mkdir()
        write_exr(root / "gt" / "envmap.exr", np.ones((4, 8, 3), np.float32))
        write_exr(root / "gt" / "albedo.exr", np.full((16, 16, 3), 0.5, np.float32))
    return root


def edit_transforms(root: Path, edit: Callable[[dict], None]) -> None:
    """Apply `edit` to the parsed transforms.json and write it back."""
    data = json.loads((root / "transforms.json").read_text())
    edit(data)
    (root / "transforms.json").write_text(json.dumps(data))


def garbage(path: Path) -> None:
    """Overwrite a file with bytes no reader accepts."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"this is not a valid file\x00\x01")
