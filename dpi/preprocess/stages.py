"""Preprocessing stages as functions of paths and settings: what the rules `capture`, `poses`, `masks`,
`geometry` and `uv` (and `dpi preprocess`) run. Each reads capture.json plus the outputs of the
stages before it, and writes its outputs and a summary (counts, errors, seconds) where dpi.layout
puts them.

Which stages a capture needs (`needed_stages`) and which derived files each reads (`stage_inputs`)
are decided here once, from what the capture gives; the rules and `dpi preprocess` both ask.
`dpi.capture.complete_capture` gives the later stages the capture with the derived inputs filled in.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

from dpi.cameras import Camera, read_cameras, write_transforms
from dpi.capture import (Capture, CaptureError, camera_fit_problem, inspect_capture, load_capture, read_capture_json,
                         write_capture_json)
from dpi.io.atomic import write_json
from dpi.io.images import read_mask
from dpi.layout import SUMMARY_FILE, SceneLayout, geometry_files, poses_files
from dpi.settings import settings_from_dict

STAGES = ("poses", "masks", "geometry", "uv")
SFM_FRAME = ("the cameras are structure from motion's, in its own frame (the object at the origin with radius 1, "
             "+Y up): give the mesh with its cameras (transforms.json), or leave the mesh out")
DERIVED_MASKS = ("the masks are derived (keying or GrabCut): with the cameras and the mesh right, they are wrong; "
                 "give masks/ or change the mask settings")

log = logging.getLogger(__name__)


def needed_stages(given: dict[str, bool]) -> list[str]:
    """The stages a capture needs, in order, from what it gives (`dpi.capture.inspect_capture`): poses
    without cameras, masks without masks, geometry without a mesh, uv without a mesh with UVs."""
    needed = {"poses": not given["cameras"], "masks": not given["masks"], "geometry": not given["mesh"],
              "uv": not given["mesh_has_uv"]}
    return [stage for stage in STAGES if needed[stage]]


def stage_inputs(stage: str, given: dict[str, bool], scene: SceneLayout) -> dict[str, Path]:
    """The derived files a preprocessing stage reads besides capture.json, keyed by its stage function's
    argument names: the outputs of the stages before it, for what the capture does not give."""
    cameras = {} if given["cameras"] else {"cameras_json": scene.poses["cameras"]}
    if stage == "masks":
        return {**cameras, **({} if given["cameras"] else {"points_ply": scene.poses["points"]})}
    if stage == "geometry":
        return {**cameras, **({} if given["masks"] else {"masks_dir": scene.masks})}
    if stage == "uv":
        return {} if given["mesh"] else {"mesh": scene.geometry["mesh"]}
    return {}


def check_given_mesh(capture: Capture, cameras: dict[str, Camera], masks: dict[str, Path] | None, source: Path,
                     derived: str) -> None:
    """Stop with one CaptureError naming `source` when the capture's own mesh contradicts derived cameras or
    masks (`dpi.capture.camera_fit_problem`, as validation checks given ones); `derived` says what was derived."""
    if capture.provenance["mesh"] != "given":
        return
    from dpi.preprocess.geometry import read_mesh

    problem = camera_fit_problem(read_mesh(capture.mesh), cameras, masks)
    if problem:
        raise CaptureError(f"{source}: {problem}; {derived}")


def capture_stage(capture_dir: str | Path, out_json: str | Path) -> None:
    """Validate a capture folder once and write its normalised description (capture.json), its views taken
    through a lens undistorted beside it (dpi.capture.undistort) and a glTF mesh converted to PLY (dpi.capture.mesh_convert)."""
    from dpi.capture.mesh_convert import renderable_mesh
    from dpi.capture.undistort import undistorted_capture

    scene = SceneLayout(Path(out_json).parent)
    capture = renderable_mesh(load_capture(capture_dir), scene.given_mesh_ply)
    write_capture_json(undistorted_capture(capture, scene.undistorted_dir), out_json)


def poses_stage(capture_json: str | Path, out_dir: str | Path, settings: dict | None = None, threads: int = 1) -> dict:
    """The capture's cameras into out_dir: its own COLMAP model when it brings one (dpi.capture.colmap_model; read
    as given, and brought into dpi's frame unless the capture's mesh is in the model's), else structure from
    motion on its images; cameras (transforms.json), sparse points and a summary (dpi.layout.poses_files)."""
    from dpi.capture.colmap_model import colmap_model_dir
    from dpi.capture.undistort import with_cameras
    from dpi.preprocess.sfm import SfMConfig, SfMError, normalise, read_model, run_sfm, write_points_ply

    capture = read_capture_json(capture_json)
    cfg = settings_from_dict(SfMConfig, settings)
    focal = capture.options.get("focal_length_px")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    files = poses_files(out_dir)
    images = [v.image for v in capture.views]
    start = time.perf_counter()
    given = colmap_model_dir(capture.root)
    try:
        if given is None:
            model = normalise(run_sfm(images, out_dir / "colmap", cfg, threads, focal and float(focal)))
        else:
            model = read_model(given, cfg)
            model = model if capture.provenance["mesh"] == "given" else normalise(model)
    except SfMError as exc:
        write_json(files["summary"], {"error": str(exc), **exc.summary})
        raise
    model.summary["seconds"] = round(time.perf_counter() - start, 3)
    held = {v.name for v in capture.held_out_views}
    frames = []
    for view in capture.views:
        camera = model.cameras.get(view.name)
        if camera is not None:
            camera.extras["held_out"] = view.name in held
            frames.append((f"images/{view.image.name}", camera))
    missing = [v.name for v in capture.views if v.name not in model.cameras]
    model.summary["unregistered"] = missing
    masks = ({v.name: v.mask for v in capture.views if v.name in model.cameras}
             if capture.provenance["masks"] == "given" else None)
    try:
        check_given_mesh(capture, model.cameras, masks, files["cameras"], SFM_FRAME)
    except CaptureError as exc:
        write_json(files["summary"], {**model.summary, "error": str(exc)})
        raise
    write_points_ply(files["points"], model.points, model.colors, model.on_object)
    with_cameras(capture, model.cameras, SceneLayout(Path(capture_json).parent).undistorted_dir)  # a fitted lens
    write_json(files["summary"], model.summary)
    write_json(files["cameras"], write_transforms(frames))
    return model.summary


def pinhole_capture(capture_json: str | Path, cameras_json: str | Path | None) -> Capture:
    """The capture with structure from motion's cameras (when derived), its views undistorted where the poses
    stage fitted a lens: what the masks and geometry stages work on."""
    from dpi.capture.undistort import with_cameras

    capture = read_capture_json(capture_json)
    if cameras_json is None:
        return capture
    return with_cameras(capture, read_cameras(cameras_json), SceneLayout(Path(capture_json).parent).undistorted_dir)


def set_threads(threads: int) -> None:
    """Use `threads` CPU threads in OpenCV (GrabCut, distance transforms, remapping)."""
    import cv2

    cv2.setNumThreads(max(1, int(threads)))


def masks_stage(capture_json: str | Path, out_dir: str | Path, settings: dict | None = None,
                cameras_json: str | Path | None = None, points_ply: str | Path | None = None,
                threads: int = 1) -> dict:
    """Foreground masks of every view with a camera: out_dir/{view}.png and a summary."""
    from dpi.preprocess.masks import MaskConfig, derive_masks
    from dpi.preprocess.sfm import read_points_ply

    set_threads(threads)
    capture = pinhole_capture(capture_json, cameras_json)
    cameras = {v.name: v.camera for v in capture.views if v.camera}
    points = None
    if points_ply:
        xyz, _, on_object = read_points_ply(points_ply)
        points = xyz[on_object]
    start = time.perf_counter()
    summary = derive_masks({v.name: v.image for v in capture.views}, cameras, out_dir, settings_from_dict(MaskConfig, settings),
                           points)
    summary["seconds"] = round(time.perf_counter() - start, 3)
    write_json(Path(out_dir) / SUMMARY_FILE, summary)
    check_given_mesh(capture, {n: cameras[n] for n in summary["views"]},
                     {n: Path(out_dir) / f"{n}.png" for n in summary["views"]}, Path(out_dir), DERIVED_MASKS)
    return summary


def geometry_stage(capture_json: str | Path, out_dir: str | Path, settings: dict | None = None,
                   cameras_json: str | Path | None = None, masks_dir: str | Path | None = None,
                   threads: int = 1) -> dict:
    """Carved and cleaned surface of the object into out_dir: mesh and summary (dpi.layout.geometry_files)."""
    from dpi.preprocess.geometry import GeometryConfig, reconstruct_surface, write_mesh_ply

    set_threads(threads)
    capture = pinhole_capture(capture_json, cameras_json)
    cameras = {v.name: v.camera for v in capture.views if v.camera}
    masks = ({p.stem: p for p in Path(masks_dir).glob("*.png")} if masks_dir
             else {v.name: v.mask for v in capture.views if v.mask})
    names = [v.name for v in capture.views if v.name in cameras and v.name in masks]
    if len(names) < 3:
        raise ValueError(f"{capture_json}: {len(names)} views have both a camera and a mask; carving needs at least 3")
    cfg = settings_from_dict(GeometryConfig, settings)
    images = None
    if cfg.stereo or cfg.ground:
        import torch

        from dpi.io.images import read_image

        torch.set_num_threads(max(1, threads))
        paths = {v.name: v.image for v in capture.views}
        images = [read_image(paths[n]) for n in names]
    start = time.perf_counter()
    vertices, faces, summary = reconstruct_surface([cameras[n] for n in names], [read_mask(masks[n]) for n in names],
                                                   cfg, images)
    summary["seconds"] = round(time.perf_counter() - start, 3)
    files = geometry_files(out_dir)
    write_mesh_ply(files["mesh"], vertices, faces)
    write_json(files["summary"], summary)
    return summary


def uv_stage(capture_json: str | Path, out_dir: str | Path, settings: dict | None = None,
             mesh: str | Path | None = None) -> dict:
    """UV atlas of the reconstructed mesh (or of the capture's mesh without UVs) into out_dir: mesh_uv and
    uv_summary (dpi.layout.geometry_files)."""
    from dpi.preprocess.geometry import read_mesh
    from dpi.preprocess.uv import UVConfig, uv_atlas, write_uv_mesh

    capture = read_capture_json(capture_json)
    source = Path(mesh) if mesh else capture.mesh
    if source is None:
        raise ValueError(f"{capture_json}: no mesh to parametrise (the capture has none; run the geometry stage)")
    vertices, faces = read_mesh(source)
    atlas, summary = uv_atlas(vertices, faces, settings_from_dict(UVConfig, settings))
    files = geometry_files(out_dir)
    write_uv_mesh(files["mesh_uv"], atlas)
    summary["source"] = str(source)
    write_json(files["uv_summary"], summary)
    return summary


def preprocess_scene(capture_dir: str | Path, scene: SceneLayout, settings: dict[str, Any] | None = None,
                     threads: int = 1) -> dict[str, Any]:
    """What the workflow's preprocessing rules do for one scene, without Snakemake: capture.json, then the
    stages the capture needs, in order, each reading `stage_inputs`, into the scene's results folder.
    `settings`: the config's `preprocess:` section. Returns each stage's summary, or "given"."""
    settings = settings or {}
    capture_stage(capture_dir, scene.capture_json)
    given = inspect_capture(capture_dir)
    run = {"poses": lambda: poses_stage(scene.capture_json, scene.poses_dir, settings.get("sfm"),
                                        threads),
           "masks": lambda: masks_stage(scene.capture_json, scene.masks, settings.get("masks"), threads=threads,
                                        **stage_inputs("masks", given, scene)),
           "geometry": lambda: geometry_stage(scene.capture_json, scene.geometry_dir,
                                              settings.get("geometry"), threads=threads,
                                              **stage_inputs("geometry", given, scene)),
           "uv": lambda: uv_stage(scene.capture_json, scene.geometry_dir, settings.get("uv"),
                                  **stage_inputs("uv", given, scene))}
    report: dict[str, Any] = dict.fromkeys(STAGES, "given")
    for stage in needed_stages(given):
        log.info("preprocess %s: %s", capture_dir, stage)
        report[stage] = run[stage]()
    return report
