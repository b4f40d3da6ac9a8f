"""The capture folder: one validation pass that turns raw inputs into one normalised `Capture`.

A capture folder holds `images/` (required) and optionally `transforms.json`, `masks/`,
`mesh.ply|obj`, `scene.xml` + `camera.xml` (the DPI authors' reference layout), `gt/` and
`scene.yaml`. `load_capture` reads and checks everything once, in pure Python, and stops at the
first problem with one `CaptureError` whose message starts with the offending file. Stages
downstream only see the resulting `Capture` (stored as `capture.json`), never the raw folder.
Values are typed strictly, the cameras are checked against the mesh and the masks (`dpi.consistency`),
and a capture that cannot be scored or has few views is used with a `CaptureWarning`.
`inspect_capture` is the cheap variant Snakemake uses at parse time to know which inputs exist.

Views are named by image stem and ordered naturally ("2" before "10"). Where a stem has both
an EXR and an LDR copy (the reference data ships both), the linear EXR is the input.
`Capture.image_size` is (width, height), as the camera conventions of `dpi.cameras`.
"""

from __future__ import annotations

import json
import math
import os
import re
import unicodedata
import warnings
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import numpy as np
import yaml

from dpi.atomic import write_json
from dpi.cameras import (DISTORTION_KEYS, Camera, Lens, TransformsError, camera_problem, json_value, read_cameras,
                         read_transforms)
from dpi.consistency import cameras_problem
from dpi.envmap import EnvmapLayoutError, read_envmap
from dpi.exr import EXRError, read_exr
from dpi.images import HDR_SUFFIXES, IMAGE_SUFFIXES, LDR_SUFFIXES, ImageError, decode_ldr, read_image, read_mask
from dpi.layout import SceneLayout
from dpi.mitsuba_xml import MitsubaXMLError, read_mesh_shapes, read_sensors

SCENE_YAML_KEYS = ("prior", "held_out", "radiance_scale", "object", "notes", "focal_length_px")
PRIORS = ("indoor", "outdoor")
GT_NAMES = ("envmap", "albedo", "roughness", "metallic")
MESH_NAMES = ("mesh.ply", "mesh.obj", "mesh.glb", "mesh.gltf")
GLTF_SUFFIXES = (".glb", ".gltf")
"""mesh formats Mitsuba does not read: the capture stage converts them to PLY (dpi.mesh_convert)"""
"""matched case-insensitively (mesh.PLY), as image suffixes are"""
PLY_UV_PAIRS = (("u", "v"), ("s", "t"), ("texture_u", "texture_v"), ("texture_s", "texture_t"))
PLY_HEADER_BYTES = 1 << 16
ASPECT_TOLERANCE = 1e-3
CLIPPED_WARNING_FRACTION = 0.01
"""an LDR image with at least this fraction of pixels at white gets a warning"""
MIN_IMAGE_SIZE = 8
"""an image smaller than this (px) on either side holds no shading to fit"""
MIN_TRAIN_VIEWS = 3
"""a capture with fewer training views gets a warning: too few to constrain the light and the materials"""


class CaptureError(ValueError):
    """A capture folder is unusable; the message starts with the offending file, then the problem."""


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


def natural_key(name: str) -> tuple:
    """Sort key that orders digit runs by value, so "2" sorts before "10"."""
    return tuple(int(part) if part.isdigit() else part for part in re.split(r"(\d+)", name))


def write_capture_json(capture: Capture, path: str | os.PathLike) -> None:
    """Write `capture.json` atomically."""
    write_json(path, capture.to_json())


def read_capture_json(path: str | os.PathLike) -> Capture:
    """Read a `capture.json` written by `write_capture_json`."""
    return Capture.from_json(json.loads(Path(path).read_text()))


# --- cheap checks (no image decoding) ---------------------------------------------------------


def _check_root(root: Path) -> None:
    """Fail unless the capture folder exists."""
    if not root.is_dir():
        raise CaptureError(f"{root}: capture folder does not exist")


OS_CLUTTER = ("thumbs.db", "ehthumbs.db", "desktop.ini", "icon\r")
"""files operating systems leave in a folder of photos (besides dot files such as .DS_Store), skipped"""


def view_name(name: str) -> str:
    """A view's name in one Unicode normal form (NFC): macOS writes file names decomposed, JSON files composed."""
    return unicodedata.normalize("NFC", name)


def _stems(folder: Path, what: str) -> dict[str, Path]:
    """view name (the stem, NFC) -> file of the images in a folder; EXR wins over an LDR copy, other duplicates
    are errors; dot files and OS_CLUTTER are skipped."""
    found: dict[str, Path] = {}
    for path in sorted(folder.iterdir()):
        if path.name.startswith(".") or path.name.lower() in OS_CLUTTER or path.is_dir():
            continue
        if path.suffix.lower() not in IMAGE_SUFFIXES:
            raise CaptureError(f"{path}: unsupported {what} suffix {path.suffix!r} (use {', '.join(IMAGE_SUFFIXES)})")
        stem = view_name(path.stem)
        other = found.get(stem)
        if other is None:
            found[stem] = path
        elif (path.suffix.lower() in HDR_SUFFIXES) == (other.suffix.lower() in HDR_SUFFIXES):
            raise CaptureError(f"{path}: ambiguous {what}: {other.name} has the same name")
        elif path.suffix.lower() in HDR_SUFFIXES:
            found[stem] = path
    return found


def _image_files(root: Path) -> dict[str, Path]:
    """view name -> image file, in natural order; fails on a missing or empty images/ folder."""
    folder = root / "images"
    if not folder.is_dir():
        raise CaptureError(f"{folder}: missing images folder (required)")
    images = _stems(folder, "image")
    if not images:
        raise CaptureError(f"{folder}: images folder is empty (expected {', '.join(IMAGE_SUFFIXES)} files)")
    return {name: images[name] for name in sorted(images, key=natural_key)}


def yaml_problem(exc: yaml.YAMLError) -> str:
    """A YAML parse error on one line: the problem and where."""
    mark = getattr(exc, "problem_mark", None)
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
    return f"{getattr(exc, 'problem', None) or exc}{where}"


def read_scene_options(root: str | os.PathLike) -> dict:
    """Validated contents of a capture's scene.yaml ({} without one); the workflow reads it before building the DAG."""
    path = Path(root) / "scene.yaml"
    if not path.is_file():
        return {}
    try:
        options = yaml.safe_load(path.read_text())
    except UnicodeDecodeError as exc:
        raise CaptureError(f"{path}: invalid YAML (not UTF-8 text: {exc.reason})") from exc
    except yaml.YAMLError as exc:
        raise CaptureError(f"{path}: invalid YAML ({yaml_problem(exc)})") from exc
    options = {} if options is None else options
    if not isinstance(options, dict):
        raise CaptureError(f"{path}: not a mapping of options (got {type(options).__name__})")
    unknown = sorted(str(k) for k in options if k not in SCENE_YAML_KEYS)
    if unknown:
        raise CaptureError(f"{path}: unknown keys {unknown} (allowed: {', '.join(SCENE_YAML_KEYS)})")
    if "prior" in options and options["prior"] not in PRIORS:
        raise CaptureError(f"{path}: prior must be one of {', '.join(PRIORS)}, got {options['prior']!r}")
    if "held_out" in options:
        options["held_out"] = _held_out_names(path, options["held_out"])
    for key, unit in (("radiance_scale", ""), ("focal_length_px", " (pixels)")):
        if key in options:
            options[key] = _positive_number(path, key, options[key], unit)
    for key in ("object", "notes"):
        if key in options and not isinstance(options[key], str):
            raise CaptureError(f"{path}: {key} must be a string, got {json_value(options[key])}")
    return options


def _held_out_names(path: Path, value: object) -> list[str]:
    """scene.yaml's held_out: a list of image names (strings, or integers for numbered images; not booleans)."""
    if not isinstance(value, list):
        raise CaptureError(f"{path}: held_out must be a list of image names, got {json_value(value)}")
    for i, name in enumerate(value):
        if isinstance(name, bool) or not isinstance(name, (str, int)):
            raise CaptureError(f"{path}: held_out[{i}] must be an image name (a string), got {json_value(name)}")
    return [str(name) for name in value]


def _positive_number(path: Path, key: str, value: object, unit: str) -> float:
    """A scene.yaml number that must be positive and finite (a YAML number: not a boolean, not a quoted string)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
        raise CaptureError(f"{path}: {key} must be a positive number{unit}, got {json_value(value)}")
    return float(value)


def _camera_xml(root: Path) -> Path | None:
    """The Mitsuba XML that holds the cameras: camera.xml, else scene.xml when it has sensors."""
    for name in ("camera.xml", "scene.xml"):
        path = root / name
        if path.is_file() and (name == "camera.xml" or _xml_sensors(path)):
            return path
    return None


def _xml_sensors(path: Path) -> list[Camera]:
    """Cameras of a Mitsuba XML file, as CaptureError on failure."""
    try:
        return read_sensors(path)
    except MitsubaXMLError as exc:
        raise CaptureError(str(exc)) from exc


def named_files(folder: Path, names: tuple[str, ...]) -> list[Path]:
    """The files of `folder` named one of `names` when case is ignored (mesh.PLY for mesh.ply), in that order."""
    files = [p for p in sorted(folder.iterdir()) if p.is_file()] if folder.is_dir() else []
    return [p for name in names for p in files if p.name.lower() == name]


def _mesh_file(root: Path, options: dict) -> Path | None:
    """The given mesh: mesh.ply / .obj / .glb / .gltf (any case), else scene.xml's mesh shape (the one named `object`
    if several)."""
    given = named_files(root, MESH_NAMES)
    if len(given) > 1:
        raise CaptureError(f"{given[1]}: ambiguous mesh, {given[0].name} is also given")
    if given:
        return given[0]
    scene = root / "scene.xml"
    if not scene.is_file():
        return None
    try:
        shapes = read_mesh_shapes(scene)
    except MitsubaXMLError as exc:
        raise CaptureError(str(exc)) from exc
    if len(shapes) > 1:
        chosen = [s for s in shapes if options.get("object") in (s.id, s.filename.stem)]
        if len(chosen) != 1:
            raise CaptureError(f"{scene}: {len(shapes)} mesh shapes ({', '.join(s.filename.name for s in shapes)}); "
                               f"name the object's shape id or file stem with `object` in scene.yaml")
        shapes = chosen
    return shapes[0].filename if shapes else None


def _ply_vertex_properties(path: Path) -> set[str]:
    """Names of the vertex properties in a PLY header (empty if it is not a PLY file)."""
    with open(path, "rb") as f:
        head = f.read(PLY_HEADER_BYTES)
    if not head.startswith(b"ply"):
        return set()
    names, in_vertex = set(), False
    for line in head.split(b"end_header")[0].decode("ascii", "replace").splitlines():
        words = line.split()
        if words[:1] == ["element"]:
            in_vertex = words[1:2] == ["vertex"]
        elif words[:1] == ["property"] and in_vertex:
            names.add(words[-1])
    return names


def mesh_has_uv(path: str | os.PathLike) -> bool:
    """Whether a PLY (u/v, s/t, texture_u/v vertex properties), OBJ (`vt` lines) or glTF (TEXCOORD_0, through
    trimesh) mesh carries UVs."""
    path = Path(path)
    if path.suffix.lower() in GLTF_SUFFIXES:
        import trimesh

        mesh = trimesh.load(path, force="mesh", process=False)
        return getattr(mesh.visual, "uv", None) is not None and len(mesh.visual.uv) == len(mesh.vertices)
    if path.suffix.lower() == ".ply":
        names = _ply_vertex_properties(path)
        return any(u in names and v in names for u, v in PLY_UV_PAIRS)
    with open(path, "rb") as f:
        return any(line[:3] in (b"vt ", b"vt\t") for line in f)


def inspect_capture(root: str | os.PathLike) -> dict[str, bool]:
    """Which inputs a capture gives (cameras, masks, mesh, mesh_has_uv), without decoding images."""
    root = Path(root)
    _check_root(root)
    mesh = _mesh_file(root, read_scene_options(root))
    return {
        "cameras": (root / "transforms.json").is_file() or _camera_xml(root) is not None,
        "masks": (root / "masks").is_dir() or _names_masks(root / "transforms.json"),
        "mesh": mesh is not None,
        "mesh_has_uv": mesh is not None and mesh.is_file() and mesh_has_uv(mesh),
    }


def derived_inputs(given: dict[str, bool], scene: SceneLayout) -> dict[str, Path]:
    """What the preprocessing stages derive for a capture that lacks it (keys cameras, masks, mesh), from
    what it gives (`inspect_capture`, `Capture.given`): the files that complete it for init, the methods
    and evaluation (dpi.preprocess.stages schedules the stages that make them)."""
    inputs = {}
    if not given["cameras"]:
        inputs["cameras"] = scene.poses["cameras"]
    if not given["masks"]:
        inputs["masks"] = scene.masks
    if not given["mesh_has_uv"]:
        inputs["mesh"] = scene.geometry["mesh_uv"]
    return inputs


def complete_capture(capture: Capture, scene: SceneLayout) -> Capture:
    """The capture with the cameras, masks and UV mesh that preprocessing derived (in the scene's results
    folder) filled in where the capture folder lacks them."""
    derived: dict = {}
    for key, path in derived_inputs(capture.given, scene).items():
        if not path.exists():
            raise FileNotFoundError(f"{path}: the capture has no {key}; run the preprocessing stages first "
                                    "(`dpi preprocess`, or the workflow)")
        if key == "cameras":
            derived["cameras"] = read_cameras(path)
        elif key == "masks":
            derived["masks"] = {p.stem: p for p in path.glob("*.png")}
        else:
            derived["mesh"] = path
    return capture.with_derived(**derived) if derived else capture


# --- full validation ------------------------------------------------------------------------


def _check_images(images: dict[str, Path]) -> tuple[int, int]:
    """Decode every image (finite, non-negative, with signal, all the same size); returns (width, height)."""
    size, first = None, None
    for path in images.values():
        try:
            image = read_image(path)
        except ImageError as exc:
            raise CaptureError(str(exc)) from exc
        height, width = image.shape[:2]
        if min(width, height) < MIN_IMAGE_SIZE:
            raise CaptureError(f"{path}: image is {width}x{height} px; dpi needs at least {MIN_IMAGE_SIZE} px on each "
                               "side (a photo or a render of the object, not a thumbnail)")
        _check_signal(path, image)
        if size is None:
            size, first = (width, height), path
        elif (width, height) != size:
            raise CaptureError(f"{path}: image size {width}x{height} differs from {first.name} ({size[0]}x{size[1]})")
    return size


def _check_signal(path: Path, image: np.ndarray) -> None:
    """Fail on an image without signal (all black, or every pixel clipped: at white for PNG/JPG, at one value
    for EXR); warn with the fraction when at least CLIPPED_WARNING_FRACTION of an LDR image's pixels are white."""
    peak = float(image.max())
    if peak == 0:
        raise CaptureError(f"{path}: image is all black (every pixel 0): nothing to fit")
    ldr = path.suffix.lower() in LDR_SUFFIXES
    white = 1.0 if ldr else peak
    clipped = float((image >= white).any(axis=-1).mean())
    if clipped == 1.0:
        raise CaptureError(f"{path}: every pixel is clipped at {white:g} (saturated): no shading to fit")
    if ldr and clipped >= CLIPPED_WARNING_FRACTION:
        warnings.warn(f"{path}: {100 * clipped:.1f}% of the pixels are clipped at white; the fit takes them as "
                      "exact, so shading there is underestimated", CaptureWarning, stacklevel=2)


def _fit_camera(source: Path, camera: Camera, size: tuple[int, int], name: str) -> Camera:
    """The camera (checked by `camera_problem`) for an image of `size`: rescaled intrinsics when only the
    resolution differs."""
    problem = camera_problem(camera)
    if problem:
        raise CaptureError(f"{source}: camera of {name}: {problem}")
    if (camera.width, camera.height) != size:
        if abs(camera.width / camera.height - size[0] / size[1]) > ASPECT_TOLERANCE:
            raise CaptureError(f"{source}: camera of {name} is {camera.width}x{camera.height}, "
                               f"image size is {size[0]}x{size[1]} (aspect ratios differ)")
        camera = camera.resized(*size)
    camera.name = name
    return camera


def _frame_name(file_path: str) -> str:
    """View name a transforms.json file_path refers to ("./images/r_0.png", "r_0" -> "r_0")."""
    name = PurePosixPath(str(file_path).replace("\\", "/")).name
    return view_name(Path(name).stem if Path(name).suffix.lower() in IMAGE_SUFFIXES else name)


def _transforms_json(path: Path) -> dict:
    """A parsed transforms.json, checked to hold a 'frames' list of frames with a file path and a pose."""
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CaptureError(f"{path}: unreadable JSON ({exc})") from exc
    if not isinstance(data, dict) or not isinstance(data.get("frames"), list):
        raise CaptureError(f"{path}: missing 'frames' list")
    for i, frame in enumerate(data["frames"]):
        if not isinstance(frame, dict) or "file_path" not in frame or "transform_matrix" not in frame:
            raise CaptureError(f"{path}: frame {i} needs 'file_path' and 'transform_matrix'")
    return data


def _transforms_cameras(path: Path, data: dict, names: list[str], size: tuple[int, int]) -> dict[str, Camera]:
    """view name -> camera from transforms.json (`data`, parsed), checking it covers exactly the images."""
    try:
        frames = read_transforms(data, default_size=size)
    except TransformsError as exc:
        raise CaptureError(f"{path}: {exc}") from exc
    cameras: dict[str, Camera] = {}
    unmatched = []
    for file_path, camera in frames:
        name = _frame_name(file_path)
        if name in cameras:
            raise CaptureError(f"{path}: two frames for image {name!r}")
        if name not in names:
            unmatched.append(file_path)
        cameras[name] = camera
    missing = [n for n in names if n not in cameras]
    if len(frames) != len(names):
        raise CaptureError(f"{path}: camera count {len(frames)} != image count {len(names)} "
                           f"(frames without image: {unmatched or 'none'}; images without frame: {missing or 'none'})")
    if unmatched:
        raise CaptureError(f"{path}: frame {unmatched[0]!r} has no matching image in images/")
    return {n: _fit_camera(path, cameras[n], size, n) for n in names}


def _xml_cameras(path: Path, names: list[str], size: tuple[int, int]) -> dict[str, Camera]:
    """view name -> camera from the sensors of a Mitsuba XML, matched in file order to the sorted images."""
    cameras = _xml_sensors(path)
    if len(cameras) != len(names):
        raise CaptureError(f"{path}: camera count {len(cameras)} != image count {len(names)} "
                           f"(sensors are matched to images in sorted order)")
    return {n: _fit_camera(path, c, size, n) for n, c in zip(names, cameras)}


def _frame_masks(path: Path, data: dict) -> dict[str, Path] | None:
    """view name -> mask file from transforms.json frames' `mask_path` (nerfstudio; relative to the file), or None
    where no frame names one."""
    frames = data["frames"]
    named = [f for f in frames if "mask_path" in f]
    if not named:
        return None
    if len(named) != len(frames):
        raise CaptureError(f"{path}: {len(frames) - len(named)} of {len(frames)} frames lack 'mask_path' "
                           "(give one per frame, or masks/ beside images/)")
    masks = {}
    for frame in named:
        if not isinstance(frame["mask_path"], str):
            raise CaptureError(f"{path}: frame {frame['file_path']!r}: 'mask_path' must be a string")
        masks[_frame_name(frame["file_path"])] = (path.parent / frame["mask_path"]).resolve()
    return masks


def _names_masks(path: Path) -> bool:
    """Whether a transforms.json exists and a frame of it names a `mask_path` (a broken file: False; load_capture
    names its problem)."""
    try:
        return path.is_file() and any("mask_path" in f for f in json.loads(path.read_text()).get("frames", []))
    except (json.JSONDecodeError, UnicodeDecodeError, AttributeError, TypeError):
        return False


def _mask_files(root: Path, images: dict[str, Path], size: tuple[int, int],
                given: dict[str, Path] | None = None) -> dict[str, Path] | None:
    """view name -> mask file: `given` (transforms.json's mask_path) or masks/ (None without either), checking one
    non-empty mask of the right size per image."""
    folder = root / "masks"
    if given is None and not folder.is_dir():
        return None
    masks = given if given is not None else _stems(folder, "mask")
    for name in masks:
        if name not in images:
            raise CaptureError(f"{masks[name]}: mask has no matching image in images/")
    for name in images:
        if name not in masks:
            raise CaptureError(f"{folder}: missing mask for image {images[name].name} (expected {name}.png)")
        try:
            mask = read_mask(masks[name])
        except ImageError as exc:
            raise CaptureError(str(exc)) from exc
        if (mask.shape[1], mask.shape[0]) != size:
            raise CaptureError(f"{masks[name]}: mask size {mask.shape[1]}x{mask.shape[0]} != "
                               f"image size {size[0]}x{size[1]}")
        if not mask.any():
            top = float(decode_ldr(masks[name]).max()) if masks[name].suffix.lower() in LDR_SUFFIXES else 0.0
            hint = (f"; its largest value is {round(top * 255)} of 255: masks stored as 0/1 must be scaled to 0/255"
                    if 0 < top <= 1 / 255 + 1e-6 else "")
            raise CaptureError(f"{masks[name]}: empty mask (no foreground pixel){hint}")
        if mask.all():
            raise CaptureError(f"{masks[name]}: mask is all foreground (every pixel white): a mask is white on the "
                               "object and black on the background")
    return masks


def _check_mesh(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's vertices and faces, failing unless the file loads with trimesh, has faces indexing its
    vertices, and finite vertices and UVs."""
    import trimesh

    if not path.is_file():
        raise CaptureError(f"{path}: mesh file does not exist")
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many exception types for bad files
        raise CaptureError(f"{path}: unreadable mesh ({exc})") from exc
    if len(getattr(mesh, "faces", [])) == 0:
        raise CaptureError(f"{path}: mesh has no faces")
    bad = int((~np.isfinite(mesh.vertices)).any(axis=1).sum())
    if bad:
        raise CaptureError(f"{path}: {bad} of {len(mesh.vertices)} mesh vertices have NaN or Inf coordinates")
    if mesh.faces.min() < 0 or mesh.faces.max() >= len(mesh.vertices):
        raise CaptureError(f"{path}: faces index vertices outside 0..{len(mesh.vertices) - 1}")
    uv = getattr(mesh.visual, "uv", None)
    if uv is not None and not np.isfinite(uv).all():
        raise CaptureError(f"{path}: mesh UVs contain NaN or Inf values")
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def read_ground_truth(path: str | os.PathLike, name: str, log: bool = False) -> np.ndarray:
    """A ground-truth map, the one reader of gt/*.exr: the envmap (H, 2H, 3) through `dpi.envmap.read_envmap`
    (any layout it reads; `log` prints its changes), a texture (albedo (H, W, 3), grey repeated; roughness,
    metallic (H, W, 1), the first channel, as `MaterialTextures.load`); NaN, Inf or negative values are an
    EXRError naming the file."""
    if name == "envmap":
        return read_envmap(path, log=log)
    data = read_exr(path)
    if not np.isfinite(data).all() or (data < 0).any():
        raise EXRError(f"{path}: ground truth {name} has NaN, Inf or negative values")
    channels = 3 if name == "albedo" else 1
    return np.repeat(data, 3, axis=-1) if data.shape[-1] < channels else data[..., :channels]


def _gt_files(root: Path) -> dict[str, Path]:
    """name -> ground-truth EXR (gt/{name}.exr, any case), each read as every stage reads it (`read_ground_truth`)."""
    gt = {}
    for name in GT_NAMES:
        for path in named_files(root / "gt", (f"{name}.exr",))[:1]:
            try:
                read_ground_truth(path, name)
            except (EXRError, EnvmapLayoutError) as exc:
                raise CaptureError(str(exc)) from exc
            gt[name] = path
    return gt


def _held_out(root: Path, names: list[str], options: dict, cameras: dict[str, Camera]) -> set[str]:
    """Held-out view names: scene.yaml's list when given, else the frames flagged `held_out`."""
    if "held_out" in options:
        unknown = [n for n in options["held_out"] if n not in names]
        if unknown:
            raise CaptureError(f"{root / 'scene.yaml'}: held_out names unknown views {unknown}")
        held = set(options["held_out"])
        source = root / "scene.yaml"
    else:
        held = {n for n, c in cameras.items() if bool(c.extras.get("held_out", False))}
        source = root / "transforms.json"
    if held and len(held) == len(names):
        raise CaptureError(f"{source}: every view is held out, none is left for training")
    return held


def camera_fit_problem(mesh: tuple[np.ndarray, np.ndarray], cameras: dict[str, Camera],
                       masks: dict[str, Path] | None) -> str | None:
    """Why the cameras contradict the mesh and the masks (or, without masks, the image frames), or None:
    `dpi.consistency.cameras_problem` over the views with a camera."""
    names = list(cameras)
    return cameras_problem(*mesh, [cameras[n] for n in names],
                           None if masks is None else [read_mask(masks[n]) for n in names], names)


def capture_warnings(capture: Capture) -> list[str]:
    """Why a usable capture gives weak results, a line each: nothing held out (no novel-view score), or fewer
    than MIN_TRAIN_VIEWS training views (too few to constrain light and materials); the log and the report
    show them."""
    lines = []
    if not capture.held_out_views:
        lines.append(f"{capture.root}: no held-out view, so the novel-view metrics (PSNR, SSIM, LPIPS) cannot be "
                     "scored; flag views `held_out` in transforms.json or list them in scene.yaml")
    if len(capture.train_views) < MIN_TRAIN_VIEWS:
        lines.append(f"{capture.root}: only {len(capture.train_views)} training view(s): too few to constrain the "
                     f"illumination and the materials (use {MIN_TRAIN_VIEWS} or more, dozens for a good fit)")
    return lines


def load_capture(root: str | os.PathLike) -> Capture:
    """Read and validate a whole capture folder; raises one CaptureError naming the first bad file, and warns
    (CaptureWarning) about a capture that cannot be scored or has too few views (`capture_warnings`)."""
    root = Path(root).resolve()
    _check_root(root)
    options = read_scene_options(root)
    images = _image_files(root)
    names = list(images)
    size = _check_images(images)
    camera_file = root / "transforms.json" if (root / "transforms.json").is_file() else _camera_xml(root)
    transforms = _transforms_json(camera_file) if camera_file is not None and camera_file.suffix == ".json" else None
    if camera_file is None:
        cameras = {}
    elif transforms is not None:
        cameras = _transforms_cameras(camera_file, transforms, names, size)
    else:
        cameras = _xml_cameras(camera_file, names, size)
    masks = _mask_files(root, images, size, _frame_masks(camera_file, transforms) if transforms is not None else None)
    mesh = _mesh_file(root, options)
    if mesh is not None:
        surface = _check_mesh(mesh)
        problem = camera_fit_problem(surface, cameras, masks) if cameras else None
        if problem:
            raise CaptureError(f"{camera_file}: {problem}")
    has_uv = mesh is not None and mesh_has_uv(mesh)
    gt = _gt_files(root)
    held = _held_out(root, names, options, cameras)
    views = [View(n, images[n], None if masks is None else masks[n], cameras.get(n), n in held) for n in names]
    provenance = {
        "cameras": "given" if cameras else "derived",
        "masks": "given" if masks is not None else "derived",
        "mesh": "given" if mesh is not None else "derived",
        "uv": "given" if has_uv else "derived",
    }
    capture = Capture(root, views, mesh, has_uv, gt, options, provenance, size)
    for line in capture_warnings(capture):
        warnings.warn(line, CaptureWarning, stacklevel=2)
    return capture
