"""The validated capture (`Capture`, its `View`s) and its JSON form, capture.json; the errors a capture raises."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dpi.capture.cameras import DISTORTION_KEYS, Camera, Lens
from dpi.io.atomic import write_json


class CaptureError(ValueError):
    """A capture folder is unusable; the message starts with the offending file, then the problem."""


def inside_capture(root: str | os.PathLike, path: str | os.PathLike, what: str) -> Path:
    """`path` resolved (links followed), when it lies inside the capture folder `root`; else one CaptureError
    naming it: a capture reads nothing from elsewhere on the host."""
    try:
        resolved = Path(path).resolve()
    except (RuntimeError, OSError):  # Python raises RuntimeError on a loop of links
        raise CaptureError(f"{path}: {what} is a link that loops or cannot be followed") from None
    if not resolved.is_relative_to(Path(root).resolve()):
        raise CaptureError(f"{path}: {what} lies outside the capture folder {root} (a link or a path out of it); "
                           "dpi reads only files inside a capture: copy the file in")
    return resolved


class CaptureWarning(UserWarning):
    """A capture is usable but part of it is not (clipped pixels, nothing held out, too few views); the message
    starts with the file."""


@dataclass
class View:
    """One input image with its optional mask and camera, and whether it is held out for evaluation."""

    name: str
    image: Path
    mask: Path | None
    camera: Camera | None
    held_out: bool


@dataclass
class Capture:
    """The validated, normalised description of a capture folder that every stage works from.

    `provenance` maps cameras, masks, mesh and uv to "given" or "derived" (a later stage computes
    it); `image_size` is (width, height); `options` is the validated scene.yaml.
    """

    root: Path
    views: list[View]
    mesh: Path | None
    mesh_has_uv: bool
    gt: dict[str, Path]
    options: dict
    provenance: dict[str, str]
    image_size: tuple[int, int]

    @property
    def train_views(self) -> list[View]:
        """Views the reconstruction fits."""
        return [v for v in self.views if not v.held_out]

    @property
    def held_out_views(self) -> list[View]:
        """Views kept aside for novel-view evaluation."""
        return [v for v in self.views if v.held_out]

    @property
    def given(self) -> dict[str, bool]:
        """What the capture folder gave, as `inspect_capture` reports it (cameras, masks, mesh, mesh_has_uv)."""
        return {key: self.provenance[name] == "given"
                for key, name in (("cameras", "cameras"), ("masks", "masks"), ("mesh", "mesh"), ("mesh_has_uv", "uv"))}

    def with_derived(self, cameras: dict[str, Camera] | None = None, masks: dict[str, Path] | None = None,
                     mesh: Path | None = None) -> "Capture":
        """This capture completed by derived inputs (the preprocessing stages' outputs).

        cameras: view name -> Camera (views without one, e.g. images structure from motion could not
        register, are dropped); masks: view name -> mask file; mesh: a mesh with UVs. Provenance is
        unchanged: it records what the capture folder gave.
        """
        views = []
        for v in self.views:
            camera = v.camera if cameras is None else cameras.get(v.name)
            if cameras is not None and camera is None:
                continue
            mask = v.mask if masks is None else masks.get(v.name)
            views.append(View(v.name, v.image, mask, camera, v.held_out))
        return Capture(self.root, views, self.mesh if mesh is None else Path(mesh),
                       self.mesh_has_uv if mesh is None else True, dict(self.gt), dict(self.options),
                       dict(self.provenance), self.image_size)

    def to_json(self) -> dict:
        """JSON-ready dict (absolute paths as strings) that `from_json` turns back into an equal Capture."""
        return {
            "root": str(self.root),
            "image_size": list(self.image_size),
            "views": [{
                "name": v.name,
                "image": str(v.image),
                "mask": None if v.mask is None else str(v.mask),
                "camera": None if v.camera is None else camera_to_json(v.camera),
                "held_out": v.held_out,
            } for v in self.views],
            "mesh": None if self.mesh is None else str(self.mesh),
            "mesh_has_uv": self.mesh_has_uv,
            "gt": {k: str(p) for k, p in self.gt.items()},
            "options": self.options,
            "provenance": self.provenance,
        }

    @classmethod
    def from_json(cls, d: dict) -> "Capture":
        """Capture from the dict written by `to_json`."""
        views = [View(v["name"], Path(v["image"]), None if v["mask"] is None else Path(v["mask"]),
                      None if v["camera"] is None else camera_from_json(v["camera"]), bool(v["held_out"]))
                 for v in d["views"]]
        return cls(Path(d["root"]), views, None if d["mesh"] is None else Path(d["mesh"]),
                   bool(d["mesh_has_uv"]), {k: Path(p) for k, p in d["gt"].items()}, dict(d["options"]),
                   dict(d["provenance"]), (int(d["image_size"][0]), int(d["image_size"][1])))


def camera_to_json(camera: Camera) -> dict:
    """JSON-ready dict of a Camera (floats survive JSON exactly)."""
    return {"c2w": np.asarray(camera.c2w, dtype=np.float64).tolist(), "width": camera.width,
            "height": camera.height, "fx": camera.fx, "fy": camera.fy, "cx": camera.cx, "cy": camera.cy,
            "name": camera.name, "extras": camera.extras,
            **({"lens": {"fisheye": camera.lens.fisheye, **{k: getattr(camera.lens, k) for k in DISTORTION_KEYS}}}
               if camera.lens else {})}


def camera_from_json(d: dict) -> Camera:
    """Camera from the dict written by `camera_to_json`."""
    return Camera(np.asarray(d["c2w"], dtype=np.float64), int(d["width"]), int(d["height"]), float(d["fx"]),
                  float(d["fy"]), float(d["cx"]), float(d["cy"]), str(d["name"]), dict(d["extras"]),
                  Lens(**d["lens"]) if d.get("lens") else None)


def write_capture_json(capture: Capture, path: str | os.PathLike) -> None:
    """Write `capture.json` atomically."""
    write_json(path, capture.to_json())


def read_capture_json(path: str | os.PathLike) -> Capture:
    """Read a `capture.json` written by `write_capture_json`."""
    return Capture.from_json(json.loads(Path(path).read_text()))
