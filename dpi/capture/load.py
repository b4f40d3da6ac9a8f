"""One validation pass over a capture folder (`load_capture`), the cheap look Snakemake takes at parse time
(`inspect_capture`), and the capture completed by what preprocessing derived."""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np

from dpi.capture.cameras import Camera, read_cameras
from dpi.capture.bundler import bundler_file, check_bundler
from dpi.capture.colmap_model import check_colmap_model, colmap_model_dir
from dpi.capture.consistency import cameras_problem
from dpi.capture.folder import alpha_masks, check_images, check_root, gt_files, image_files, mask_files
from dpi.capture.meshes import check_mesh, mesh_file, mesh_has_uv, true_surface
from dpi.capture.mitsuba_scene import camera_xml, xml_cameras
from dpi.capture.model import Capture, CaptureError, CaptureWarning, View
from dpi.capture.nerf_synthetic import read_splits, split_files
from dpi.capture.scene_yaml import read_scene_options
from dpi.capture.transforms import frame_masks, names_masks, read_transforms_json, transforms_cameras
from dpi.capture.undistort import with_cameras
from dpi.io.images import read_mask
from dpi.io.layout import SceneLayout

MIN_TRAIN_VIEWS = 3
"""a capture with fewer training views gets a warning: too few to constrain the light and the materials"""
MIN_DERIVED_VIEWS = 3
"""photos a capture whose cameras come from its photos needs: structure from motion registers a pair, and each
derived mask is checked against the others' (two at least)"""


def inspect_capture(root: str | os.PathLike) -> dict[str, bool]:
    """Which inputs a capture gives (cameras, masks, mesh, mesh_has_uv), without decoding images."""
    root = Path(root)
    check_root(root)
    mesh = mesh_file(root, read_scene_options(root))
    nerf = nerf_synthetic(root)
    images = read_splits(root)[0] if nerf else image_files(root) if (root / "images").is_dir() else {}
    return {
        "cameras": (root / "transforms.json").is_file() or nerf or camera_xml(root) is not None,
        "masks": (root / "masks").is_dir() or names_masks(root / "transforms.json") or alpha_masks(images) is not None,
        "mesh": mesh is not None,
        "mesh_has_uv": mesh is not None and mesh.is_file() and mesh_has_uv(mesh),
    }


def nerf_synthetic(root: Path) -> bool:
    """Whether the capture is in the NeRF-synthetic layout: split files (transforms_train.json, ...) and no
    transforms.json."""
    return bool(split_files(root)) and not (root / "transforms.json").is_file()


def derived_inputs(given: dict[str, bool], scene: SceneLayout) -> dict[str, Path]:
    """What the preprocessing stages derive for a capture that lacks it (keys cameras, masks, mesh), from
    what it gives (`inspect_capture`, `Capture.given`): the files that complete it for init, the methods
    and evaluation (dpi.stages.preprocess schedules the stages that make them)."""
    inputs = {}
    if not given["cameras"]:
        inputs["cameras"] = scene.poses["cameras"]
    if not given["masks"]:
        inputs["masks"] = scene.masks
    if not given["mesh_has_uv"]:
        inputs["mesh"] = scene.geometry["mesh_uv"]
    return inputs


def complete_capture(capture: Capture, scene: SceneLayout, keys: tuple[str, ...] = ("cameras", "masks", "mesh")
                     ) -> Capture:
    """The capture with the cameras, masks and UV mesh that preprocessing derived (in the scene's results
    folder) filled in where the capture folder lacks them (those of `keys`: a stage before the last needs fewer)."""
    derived: dict = {}
    for key, path in derived_inputs(capture.given, scene).items():
        if key not in keys:
            continue
        if not path.exists():
            raise FileNotFoundError(f"{path}: the capture has no {key}; run the preprocessing stages first "
                                    "(`dpi preprocess`, or the workflow)")
        if key == "cameras":
            capture = with_cameras(capture, read_cameras(path), scene.undistorted_dir)
        elif key == "masks":
            derived["masks"] = {p.stem: p for p in path.glob("*.png")}
        else:
            derived["mesh"] = path
    return capture.with_derived(**derived) if derived else capture


def held_out_names(root: Path, names: list[str], options: dict, cameras: dict[str, Camera],
                   camera_file: Path | None) -> set[str]:
    """Held-out view names: scene.yaml's list when given, else the frames flagged `held_out` in `camera_file` (a
    NeRF-synthetic capture's: its test split)."""
    if "held_out" in options:
        unknown = [n for n in options["held_out"] if n not in names]
        if unknown:
            raise CaptureError(f"{root / 'scene.yaml'}: held_out names unknown views {unknown}")
        held = set(options["held_out"])
        source = root / "scene.yaml"
    else:
        held = {n for n, c in cameras.items() if bool(c.extras.get("held_out", False))}
        source = camera_file or root / "transforms.json"
    if held and len(held) == len(names):
        raise CaptureError(f"{source}: every view is held out, none is left for training")
    return held


def camera_fit_problem(mesh: tuple[np.ndarray, np.ndarray], cameras: dict[str, Camera],
                       masks: dict[str, Path] | None) -> str | None:
    """Why the cameras contradict the mesh and the masks (or, without masks, the image frames), or None:
    `dpi.capture.consistency.cameras_problem` over the views with a camera."""
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
    check_root(root)
    options = read_scene_options(root)
    if nerf_synthetic(root):
        images, transforms = read_splits(root)
        camera_file = next(iter(split_files(root).values()))
    else:
        images = image_files(root)
        transforms_file = root / "transforms.json"
        camera_file = transforms_file if transforms_file.is_file() else camera_xml(root)
        transforms = read_transforms_json(camera_file) if camera_file is not None and camera_file.suffix == ".json" \
            else None
    names = list(images)
    model_dir = colmap_model_dir(root) if camera_file is None else None
    bundle = bundler_file(root) if camera_file is None and model_dir is None else None
    from_photos = camera_file is None and model_dir is None and bundle is None
    if from_photos and len(images) < MIN_DERIVED_VIEWS:
        raise CaptureError(f"{root / 'images'}: {len(images)} photo(s) and no cameras: the cameras and masks come "
                           f"from the photos, which takes {MIN_DERIVED_VIEWS} or more taken from different places "
                           "around the object (dozens for a good fit)")
    size = check_images(images, distinct=from_photos)
    if model_dir is not None:
        check_colmap_model(root, model_dir, names, size)
    if bundle is not None:
        check_bundler(root, bundle, images, size)
    if camera_file is None:
        cameras = {}
    elif transforms is not None:
        cameras = transforms_cameras(camera_file, transforms, names, size)
    else:
        cameras = xml_cameras(camera_file, names, size)
    given_masks = frame_masks(camera_file, transforms) if transforms is not None else None
    if given_masks is None and not (root / "masks").is_dir():
        given_masks = alpha_masks(images)
    masks = mask_files(root, images, size, given_masks)
    mesh = mesh_file(root, options)
    if mesh is not None:
        surface = check_mesh(mesh)
        problem = camera_fit_problem(surface, cameras, masks) if cameras else None
        if problem:
            raise CaptureError(f"{camera_file}: {problem}")
    has_uv = mesh is not None and mesh_has_uv(mesh)
    gt = {**gt_files(root), **true_surface(root)}
    held = held_out_names(root, names, options, cameras, camera_file)
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
