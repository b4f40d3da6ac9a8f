"""Preprocessing stages as functions of paths and settings: what the rules `poses`, `masks`,
`geometry` and `uv` (and `dpi preprocess ...`) run. Each reads capture.json plus the outputs of the
stages before it, and writes its own outputs and a `summary.json` (counts, errors, seconds).

Results layout (next to capture.json, in results/{scene}/):

    poses/transforms.json, poses/points.ply, poses/summary.json   cameras from COLMAP, sparse points
    masks/{view}.png, masks/summary.json                          foreground masks
    geometry/mesh.ply, geometry/summary.json                      carved, cleaned surface
    geometry/mesh_uv.ply                                          the surface with a UV atlas

`complete_capture` gives later stages the capture with these derived inputs filled in.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path
from typing import Any

from dpi.atomic import write_json
from dpi.cameras import Camera, read_transforms, write_transforms
from dpi.capture import Capture, read_capture_json
from dpi.images import read_mask
from dpi.settings import settings_from_dict

log = logging.getLogger(__name__)

POSES = Path("poses") / "transforms.json"
POINTS = Path("poses") / "points.ply"
MASKS = Path("masks")
MESH = Path("geometry") / "mesh.ply"
MESH_UV = Path("geometry") / "mesh_uv.ply"


def read_cameras(path: str | Path) -> dict[str, Camera]:
    """view name -> Camera from a transforms.json (file paths "images/{view}.png" or "{view}")."""
    frames = read_transforms(json.loads(Path(path).read_text()))
    cameras = {}
    for file_path, camera in frames:
        name = Path(file_path).stem
        camera.name = name
        cameras[name] = camera
    return cameras


def complete_capture(capture: Capture, results_dir: str | Path, paths: dict[str, str | Path] | None = None) -> Capture:
    """The capture with the derived cameras, masks and UV mesh of the preprocessing stages filled in
    wherever its provenance says "derived". `paths` overrides the default locations in results_dir
    (keys cameras, masks, mesh)."""
    results_dir, paths = Path(results_dir), dict(paths or {})
    derived = {}
    if capture.provenance.get("cameras") == "derived":
        path = Path(paths.get("cameras", results_dir / POSES))
        if not path.is_file():
            raise FileNotFoundError(f"{path}: the capture has no cameras; run the poses stage first")
        derived["cameras"] = read_cameras(path)
    if capture.provenance.get("masks") == "derived":
        folder = Path(paths.get("masks", results_dir / MASKS))
        if not folder.is_dir():
            raise FileNotFoundError(f"{folder}: the capture has no masks; run the masks stage first")
        derived["masks"] = {p.stem: p for p in folder.glob("*.png")}
    if capture.provenance.get("uv") == "derived":
        path = Path(paths.get("mesh", results_dir / MESH_UV))
        if not path.is_file():
            raise FileNotFoundError(f"{path}: the capture has no UV-mapped mesh; run the geometry and uv stages first")
        derived["mesh"] = path
    return capture.with_derived(**derived) if derived else capture


def poses_stage(capture_json: str | Path, out_dir: str | Path, settings: dict | None = None, threads: int = 1) -> dict:
    """Structure from motion on the capture's images: poses/transforms.json, points.ply, summary.json."""
    from dpi.preprocess.sfm import SfMConfig, SfMError, normalise, run_sfm, write_points_ply

    capture = read_capture_json(capture_json)
    cfg = settings_from_dict(SfMConfig, settings)
    if cfg.focal_length_px is None and "focal_length_px" in capture.options:
        cfg.focal_length_px = float(capture.options["focal_length_px"])
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    images = [v.image for v in capture.views]
    start = time.perf_counter()
    try:
        model = normalise(run_sfm(images, out_dir / "colmap", cfg, threads))
    except SfMError as exc:
        write_json(out_dir / "summary.json", {"error": str(exc), **exc.summary})
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
    write_points_ply(out_dir / "points.ply", model.points, model.colors, model.on_object)
    write_json(out_dir / "summary.json", model.summary)
    write_json(out_dir / "transforms.json", write_transforms(frames))
    return model.summary


def set_threads(threads: int) -> None:
    """Use `threads` CPU threads in OpenCV (GrabCut, distance transforms, remapping)."""
    import cv2

    cv2.setNumThreads(max(1, int(threads)))


def masks_stage(capture_json: str | Path, out_dir: str | Path, settings: dict | None = None,
                cameras_json: str | Path | None = None, points_ply: str | Path | None = None,
                threads: int = 1) -> dict:
    """Foreground masks of every view with a camera: masks/{view}.png and masks/summary.json."""
    from dpi.preprocess.masks import MaskConfig, derive_masks
    from dpi.preprocess.sfm import read_points_ply

    set_threads(threads)
    capture = read_capture_json(capture_json)
    cameras = read_cameras(cameras_json) if cameras_json else {v.name: v.camera for v in capture.views if v.camera}
    points = None
    if points_ply:
        xyz, _, on_object = read_points_ply(points_ply)
        points = xyz[on_object]
    start = time.perf_counter()
    summary = derive_masks({v.name: v.image for v in capture.views}, cameras, out_dir, settings_from_dict(MaskConfig, settings),
                           points)
    summary["seconds"] = round(time.perf_counter() - start, 3)
    write_json(Path(out_dir) / "summary.json", summary)
    return summary


def geometry_stage(capture_json: str | Path, out_mesh: str | Path, settings: dict | None = None,
                   cameras_json: str | Path | None = None, masks_dir: str | Path | None = None,
                   threads: int = 1) -> dict:
    """Carved and cleaned surface of the object: geometry/mesh.ply and geometry/summary.json."""
    from dpi.preprocess.geometry import GeometryConfig, reconstruct_surface, write_mesh_ply

    set_threads(threads)
    capture = read_capture_json(capture_json)
    cameras = read_cameras(cameras_json) if cameras_json else {v.name: v.camera for v in capture.views if v.camera}
    masks = ({p.stem: p for p in Path(masks_dir).glob("*.png")} if masks_dir
             else {v.name: v.mask for v in capture.views if v.mask})
    names = [v.name for v in capture.views if v.name in cameras and v.name in masks]
    if len(names) < 3:
        raise ValueError(f"{capture_json}: {len(names)} views have both a camera and a mask; carving needs at least 3")
    start = time.perf_counter()
    vertices, faces, summary = reconstruct_surface([cameras[n] for n in names], [read_mask(masks[n]) for n in names],
                                                   settings_from_dict(GeometryConfig, settings))
    summary["seconds"] = round(time.perf_counter() - start, 3)
    write_mesh_ply(out_mesh, vertices, faces)
    write_json(Path(out_mesh).parent / "summary.json", summary)
    return summary


def uv_stage(capture_json: str | Path, out_mesh: str | Path, settings: dict | None = None,
             mesh: str | Path | None = None) -> dict:
    """UV atlas of the reconstructed mesh (or of the capture's mesh without UVs): geometry/mesh_uv.ply."""
    from dpi.preprocess.geometry import read_mesh
    from dpi.preprocess.uv import UVConfig, uv_atlas, write_uv_mesh

    capture = read_capture_json(capture_json)
    source = Path(mesh) if mesh else capture.mesh
    if source is None:
        raise ValueError(f"{capture_json}: no mesh to parametrise (the capture has none; run the geometry stage)")
    vertices, faces = read_mesh(source)
    atlas, summary = uv_atlas(vertices, faces, settings_from_dict(UVConfig, settings))
    write_uv_mesh(out_mesh, atlas)
    summary["source"] = str(source)
    write_json(Path(out_mesh).with_name("uv_summary.json"), summary)
    return summary


STAGES = ("poses", "masks", "geometry", "uv")


def needed_stages(given: dict[str, bool]) -> list[str]:
    """The stages a capture needs, in order, from what it gives (`dpi.capture.inspect_capture`), as the
    workflow schedules them: poses without cameras, masks without masks, geometry without a mesh, uv
    without a mesh with UVs."""
    needed = {"poses": not given["cameras"], "masks": not given["masks"], "geometry": not given["mesh"],
              "uv": not given["mesh_has_uv"]}
    return [stage for stage in STAGES if needed[stage]]


def preprocess_capture(capture_dir: str | Path, results_dir: str | Path, settings: dict[str, Any] | None = None,
                       threads: int = 1) -> dict[str, Any]:
    """Derive what a capture lacks without Snakemake: capture.json, then the needed stages in order, in
    the workflow's layout under `results_dir` (its results/{scene}/). `settings`: config.yaml's
    `preprocess:` section. Returns each stage's summary, or "given"."""
    from dpi.capture import inspect_capture
    from dpi.stages import capture_stage

    results_dir, settings = Path(results_dir), settings or {}
    capture_json = results_dir / "capture.json"
    capture_stage(capture_dir, capture_json)
    stages = needed_stages(inspect_capture(capture_dir))
    cameras = results_dir / POSES if "poses" in stages else None
    points = results_dir / POINTS if "poses" in stages else None
    masks = results_dir / MASKS if "masks" in stages else None
    mesh = results_dir / MESH if "geometry" in stages else None
    report: dict[str, Any] = {stage: "given" for stage in STAGES}
    for stage in stages:
        log.info("preprocess %s: %s", capture_dir, stage)
        if stage == "poses":
            report[stage] = poses_stage(capture_json, results_dir / POSES.parent, settings.get("sfm"), threads)
        elif stage == "masks":
            report[stage] = masks_stage(capture_json, masks, settings.get("masks"), cameras, points, threads)
        elif stage == "geometry":
            report[stage] = geometry_stage(capture_json, mesh, settings.get("geometry"), cameras, masks, threads)
        else:
            report[stage] = uv_stage(capture_json, results_dir / MESH_UV, settings.get("uv"), mesh)
    return report
