"""What each preprocessing stage derives, as functions of paths and settings: a validated capture.json, then
cameras, masks, a surface and its UV atlas. Each reads capture.json plus the files of the stages before it and
writes its outputs and a summary (counts, errors, seconds) where dpi.io.layout puts them; dpi.stages.preprocess
decides which run and with what.
"""

from __future__ import annotations

import time
from pathlib import Path

from dpi.capture import (Capture, CaptureError, camera_fit_problem, load_capture, read_capture_json,
                         write_capture_json)
from dpi.capture.cameras import Camera, read_cameras, write_transforms
from dpi.io.atomic import write_json
from dpi.io.images import read_mask
from dpi.io.layout import SUMMARY_FILE, SceneLayout, geometry_files, poses_files
from dpi.io.settings import settings_from_dict
from dpi.io.structured import read_json
from dpi.render.backend import set_threads

SFM_FRAME = ("the cameras are structure from motion's, in its own frame (the object at the origin with radius 1, "
             "+Y up): give the mesh with its cameras (transforms.json), or leave the mesh out")
DERIVED_MASKS = ("the masks are derived (keying or GrabCut): with the cameras and the mesh right, they are wrong; "
                 "give masks/ or change the mask settings")


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


def normalise_capture(capture_dir: str | Path, out_json: str | Path) -> None:
    """Validate a capture folder once and write its normalised description (capture.json), its views taken
    through a lens undistorted beside it (dpi.capture.undistort) and a glTF mesh converted to PLY (dpi.capture.mesh_convert)."""
    from dpi.capture.mesh_convert import renderable_mesh
    from dpi.capture.undistort import undistorted_capture

    scene = SceneLayout(Path(out_json).parent)
    capture = renderable_mesh(load_capture(capture_dir), scene.given_mesh_ply)
    write_capture_json(undistorted_capture(capture, scene.undistorted_dir), out_json)


def derive_poses(capture_json: str | Path, out_dir: str | Path, settings: dict | None = None, threads: int = 1) -> dict:
    """The capture's cameras into out_dir: its own COLMAP model or Bundler file when it brings one
    (dpi.capture.colmap_model, dpi.capture.bundler; read as given, points triangulated under a Bundler file's
    cameras, and brought into dpi's frame unless the capture's mesh is in theirs), its given cameras with
    points triangulated under them (dpi.preprocess.known_poses: what the masks stage reads), else structure from
    motion on its images; cameras (transforms.json), sparse points and a summary (dpi.io.layout.poses_files)."""
    from dpi.capture.bundler import bundler_file, capture_bundler_cameras
    from dpi.capture.colmap_model import colmap_model_dir
    from dpi.capture.undistort import with_cameras
    from dpi.preprocess.known_poses import triangulate_known
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
    bundle = bundler_file(capture.root) if given is None else None
    in_mesh_frame = capture.provenance["mesh"] == "given"
    try:
        if capture.provenance["cameras"] == "given":
            model = triangulate_known(images, {v.name: v.camera for v in capture.views if v.camera},
                                      out_dir / "colmap", cfg, threads)
        elif given is not None:
            model = read_model(given, cfg)
            model = model if in_mesh_frame else normalise(model)
        elif bundle is not None:
            cameras = capture_bundler_cameras(capture.root, bundle, {v.name: v.image for v in capture.views},
                                              capture.image_size)
            model = triangulate_known(images, cameras, out_dir / "colmap", cfg, threads)
            model.summary["cameras"] = bundle.relative_to(capture.root).as_posix()
            model = model if in_mesh_frame else normalise(model)
        else:
            model = normalise(run_sfm(images, out_dir / "colmap", cfg, threads, focal and float(focal)))
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


def derive_view_masks(capture_json: str | Path, out_dir: str | Path, settings: dict | None = None,
                cameras_json: str | Path | None = None, points_ply: str | Path | None = None,
                threads: int = 1) -> dict:
    """Foreground masks of every view with a camera: out_dir/{view}.png and a summary."""
    from dpi.preprocess.masks import MaskConfig, derive_masks
    from dpi.preprocess.sfm import read_points_ply

    set_threads(threads)
    capture = pinhole_capture(capture_json, cameras_json)
    cameras = {v.name: v.camera for v in capture.views if v.camera}
    points = scene_points = None
    if points_ply:
        scene_points, _, on_object = read_points_ply(points_ply)
        points = scene_points[on_object]
    start = time.perf_counter()
    summary = derive_masks({v.name: v.image for v in capture.views}, cameras, out_dir, settings_from_dict(MaskConfig, settings),
                           points, scene_points)
    summary["seconds"] = round(time.perf_counter() - start, 3)
    write_json(Path(out_dir) / SUMMARY_FILE, summary)
    check_given_mesh(capture, {n: cameras[n] for n in summary["views"]},
                     {n: Path(out_dir) / f"{n}.png" for n in summary["views"]}, Path(out_dir), DERIVED_MASKS)
    return summary


def derive_geometry(capture_json: str | Path, out_dir: str | Path, settings: dict | None = None,
                   cameras_json: str | Path | None = None, masks_dir: str | Path | None = None,
                   threads: int = 1) -> dict:
    """Carved and cleaned surface of the object into out_dir: mesh and summary (dpi.io.layout.geometry_files); stops
    first when the derived masks are mostly unreliable (dpi.preprocess.mask_confidence.check_usable)."""
    from dpi.io.meshes import write_mesh_ply
    from dpi.preprocess.geometry import GeometryConfig, reconstruct_surface

    set_threads(threads)
    derived = read_json(Path(masks_dir) / SUMMARY_FILE) if masks_dir and (Path(masks_dir) / SUMMARY_FILE).is_file() \
        else None
    if derived:
        from dpi.preprocess.mask_confidence import check_usable

        check_usable(derived, str(masks_dir))
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
        from dpi.io.images import read_image

        paths = {v.name: v.image for v in capture.views}
        images = [read_image(paths[n]) for n in names]
    start = time.perf_counter()
    try:
        vertices, faces, summary = reconstruct_surface([cameras[n] for n in names],
                                                       [read_mask(masks[n]) for n in names], cfg, images)
    except ValueError as exc:
        if not derived or derived.get("prior") != "sphere":
            raise
        from dpi.preprocess.masks import WITHOUT_POINTS

        raise ValueError(f"{exc}: {WITHOUT_POINTS}") from None
    summary["seconds"] = round(time.perf_counter() - start, 3)
    files = geometry_files(out_dir)
    write_mesh_ply(files["mesh"], vertices, faces)
    write_json(files["summary"], summary)
    return summary


def derive_uv(capture_json: str | Path, out_dir: str | Path, texture_size: int, settings: dict | None = None,
              mesh: str | Path | None = None) -> dict:
    """UV atlas of the reconstructed mesh (or of the capture's mesh without UVs), packed for textures of texture_size
    texels a side, into out_dir: mesh_uv and uv_summary (dpi.io.layout.geometry_files)."""
    from dpi.preprocess.geometry import read_mesh
    from dpi.preprocess.uv import UVConfig, uv_atlas, write_uv_mesh

    capture = read_capture_json(capture_json)
    source = Path(mesh) if mesh else capture.mesh
    if source is None:
        raise ValueError(f"{capture_json}: no mesh to parametrise (the capture has none; run the geometry stage)")
    vertices, faces = read_mesh(source)
    atlas, summary = uv_atlas(vertices, faces, texture_size, settings_from_dict(UVConfig, settings))
    files = geometry_files(out_dir)
    write_uv_mesh(files["mesh_uv"], atlas)
    summary["source"] = str(source)
    write_json(files["uv_summary"], summary)
    return summary
