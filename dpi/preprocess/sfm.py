"""Camera poses from plain photos: structure from motion with COLMAP (pycolmap), normalised for dpi.

`run_sfm` runs COLMAP's classic pipeline on the capture's images: SIFT features with one camera
shared by all images (a single pinhole, or known intrinsics), exhaustive matching for small captures and
sequential matching (neighbours in file order, with loop closure off) for larger ones, whose photos a walk-around
takes in order (where that registers too few, the remaining pairs are matched too and the mapping runs again),
then incremental mapping. Registered views whose image does not contain the point all cameras look at are dropped
as misregistered (a walk-around keeps the object in frame). The model is checked (enough images registered, one
model, a small mean reprojection error) and each failure stops with an `SfMError` that carries the summary.
`normalise` then moves the model into dpi's frame: the object (the sparse points that most cameras have in view)
centred at the origin with radius 1, +Y up (the normal of the ring of cameras, signed like the cameras' own up),
and the first camera looking along -Z.

COLMAP's `cam_from_world` maps world points into OpenCV camera axes (x right, y down, looking
along +z); dpi's cameras are OpenGL camera-to-world matrices (y up, looking along -z), so
`c2w_gl = inverse(cam_from_world) @ diag(1, -1, -1, 1)`. COLMAP's pixel centres sit at
half-integers, as in `dpi.capture.cameras.pixel_rays`, so the principal point carries over unchanged.
"""

from __future__ import annotations

import logging
import shutil
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Annotated

import numpy as np
from PIL import Image, ImageOps
from pydantic import Field

from dpi.capture.cameras import Camera, Lens
from dpi.capture.colmap_model import READ_MODELS
from dpi.io.images import exif_orientation
from dpi.io.settings import Count, Fraction, settings
from dpi.preprocess.hull import axes_centre, visible_sphere

log = logging.getLogger(__name__)

CV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])
MATCHERS = ("auto", "exhaustive", "sequential")


class SfMError(RuntimeError):
    """Structure from motion failed; `summary` holds what was found (registered images, models, errors)."""

    def __init__(self, message: str, summary: dict | None = None):
        super().__init__(message)
        self.summary = summary or {}


EXHAUSTIVE_MAX_IMAGES = 40
"""largest capture matched exhaustively under matcher=auto; larger ones are matched sequentially first (a fraction
of the pairs), and exhaustively only where that registers too few images"""
INIT_MIN_INLIERS = 50
"""verified matches the initial image pair needs (COLMAP's default 100 suits large photos)"""
MIN_POSE_INLIERS = 30
"""2D-3D inliers a further image needs to be registered (COLMAP's default)"""
MIN_TRACK_LENGTH = 3
"""sparse points seen in fewer images are dropped"""
OBJECT_VIEW_FRACTION = 0.75
"""a sparse point is on the object when at least this fraction of the cameras has it in view"""
REJECT_OFF_CENTRE = True
"""drop registered views that do not have the object (the point all cameras look at) in frame:
in a walk-around capture those are misregistrations (e.g. on repetitive backgrounds)"""
SEQUENTIAL_OVERLAP = 15
"""neighbours (in file order) each image is matched with by the sequential matcher"""
PEAK_THRESHOLD = 0.004
"""SIFT contrast threshold (COLMAP's default 0.0067 finds few features in small or soft images)"""
MAX_REPROJECTION_ERROR_PX = 1.5
"""a mean reprojection error above this is an error"""
COLMAP_SEED = 0
"""the mapper's random seed (with one thread COLMAP then reproduces its poses exactly)"""
MIN_LENS_SHIFT_PX = 0.25
"""a fitted lens distortion that moves the image's corner by less than this (pixels) is dropped"""


@settings
class SfMConfig:
    """Settings of the COLMAP pipeline and of the checks on its result."""

    matcher: str = "auto"
    """auto (exhaustive up to EXHAUSTIVE_MAX_IMAGES images, else sequential, then exhaustive where that registers
    fewer than min_registered_fraction) | exhaustive | sequential"""
    max_image_size: Annotated[int, Field(ge=64)] = 1600
    """images are downscaled to this longest side for feature extraction"""
    max_features: Count = 8192
    """SIFT features per image"""
    min_registered_fraction: Fraction = 0.9
    """fewer registered images than this fraction of the capture is an error"""


@dataclass
class SparseModel:
    """Registered cameras (view name -> Camera), sparse points (N, 3) with colours (N, 3) in [0, 1],
    which points are on the object, and a summary of the run."""

    cameras: dict[str, Camera]
    points: np.ndarray
    colors: np.ndarray
    on_object: np.ndarray
    summary: dict = field(default_factory=dict)


def colmap_to_camera(cam_from_world: np.ndarray, width: int, height: int, fx: float, fy: float, cx: float,
                     cy: float, name: str, lens: Lens | None = None) -> Camera:
    """dpi Camera (OpenGL camera-to-world) from COLMAP's 3x4 world-to-camera matrix (OpenCV axes)."""
    w2c = np.eye(4)
    w2c[:3, :4] = np.asarray(cam_from_world, dtype=np.float64)
    return Camera(np.linalg.inv(w2c) @ CV_TO_GL, int(width), int(height), float(fx), float(fy), float(cx),
                  float(cy), name, lens=lens)


def lens_shift_px(lens: Lens, width: int, height: int, focal: float) -> float:
    """How far (pixels) the lens moves the image's corner: the size of the distortion the photos show."""
    corner = np.array([width / 2 / focal]), np.array([height / 2 / focal])
    x, y = lens.distort(*corner)
    return float(focal * np.hypot(x - corner[0], y - corner[1])[0])


def _intrinsics(camera) -> tuple[float, float, float, float, Lens | None]:
    """(fx, fy, cx, cy, lens) of a COLMAP camera model; a fitted radial distortion that moves no pixel by
    MIN_LENS_SHIFT_PX is dropped (the photos need no lens model)."""
    params = np.asarray(camera.params, dtype=np.float64)
    if camera.model_name == "SIMPLE_PINHOLE":
        return params[0], params[0], params[1], params[2], None
    if camera.model_name == "PINHOLE":
        return params[0], params[1], params[2], params[3], None
    if camera.model_name in ("SIMPLE_RADIAL", "RADIAL"):
        lens = Lens(k1=float(params[3]), k2=float(params[4]) if camera.model_name == "RADIAL" else 0.0)
        keep = lens_shift_px(lens, camera.width, camera.height, params[0]) >= MIN_LENS_SHIFT_PX
        return params[0], params[0], params[1], params[2], lens if keep else None
    if camera.model_name in ("OPENCV", "OPENCV_FISHEYE"):
        fisheye = camera.model_name == "OPENCV_FISHEYE"
        lens = Lens(fisheye=True, k1=float(params[4]), k2=float(params[5]), k3=float(params[6]),
                    k4=float(params[7])) if fisheye else \
            Lens(k1=float(params[4]), k2=float(params[5]), p1=float(params[6]), p2=float(params[7]))
        return params[0], params[1], params[2], params[3], lens
    raise SfMError(f"COLMAP camera model {camera.model_name} is not read by dpi (use {', '.join(READ_MODELS)})")


def upright_copies(images: list[Path], folder: Path) -> list[Path]:
    """Copies of `images` turned upright by their EXIF orientation (Pillow's exif_transpose), same names."""
    folder.mkdir(parents=True, exist_ok=True)
    copies = []
    for path in images:
        with Image.open(path) as image:
            ImageOps.exif_transpose(image).save(folder / path.name, quality=95)
        copies.append(folder / path.name)
    return copies


def fresh_work(images: list[Path], work_dir: str | Path) -> tuple[list[Path], Path, Path]:
    """An empty COLMAP work folder (with sparse/) for `images`, all in one folder: (the images as COLMAP reads them,
    upright copies where EXIF rotates them; their folder; the work folder)."""
    images = [Path(p) for p in images]
    folders = {p.parent.resolve() for p in images}
    if len(folders) != 1:
        raise ValueError("COLMAP's images must all be in one folder")
    image_dir = folders.pop()
    work = Path(work_dir)
    if work.exists():
        shutil.rmtree(work)
    (work / "sparse").mkdir(parents=True)
    if any(exif_orientation(p) != 1 for p in images):  # COLMAP reads the stored pixels; dpi reads them upright
        images = upright_copies(images, work / "upright")
        image_dir = work / "upright"
    return images, image_dir, work


def extraction_options(cfg: SfMConfig, threads: int):
    """COLMAP's SIFT extraction under the settings (image size, features, the contrast threshold)."""
    import pycolmap

    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = threads
    extraction.max_image_size = cfg.max_image_size
    extraction.sift.max_num_features = cfg.max_features
    extraction.sift.peak_threshold = PEAK_THRESHOLD
    return extraction


def match_features(database: Path, matcher: str, threads: int) -> None:
    """Match the database's images, every pair (`exhaustive`) or each with its SEQUENTIAL_OVERLAP neighbours in file
    order; pairs already matched are kept."""
    import pycolmap

    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = threads
    if matcher == "exhaustive":
        pycolmap.match_exhaustive(database, matching_options=matching, device=pycolmap.Device.cpu)
    else:
        pairing = pycolmap.SequentialPairingOptions()
        pairing.overlap = SEQUENTIAL_OVERLAP
        pairing.num_threads = threads
        pycolmap.match_sequential(database, matching_options=matching, pairing_options=pairing,
                                  device=pycolmap.Device.cpu)


def run_sfm(images: list[Path], work_dir: str | Path, cfg: SfMConfig | None = None,
            threads: int = 1, focal_length_px: float | None = None) -> SparseModel:
    """COLMAP on `images` (all in one folder; view name = file stem), in `work_dir` (database, model); a known
    `focal_length_px` (scene.yaml's) is held fixed, else it is estimated (EXIF or 1.2 x image size first).

    Returns the model in COLMAP's own frame; see `normalise`."""
    import pycolmap

    cfg = cfg or SfMConfig()
    if cfg.matcher not in MATCHERS:
        raise ValueError(f"matcher must be one of {', '.join(MATCHERS)}, got {cfg.matcher!r}")
    images, image_dir, work = fresh_work(images, work_dir)
    database = work / "database.db"
    times = {}

    start = time.perf_counter()
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = "SIMPLE_RADIAL"  # a pinhole and one radial term, fitted with the poses (COLMAP's default)
    if focal_length_px:
        with Image.open(images[0]) as im:
            width, height = im.size
        reader.camera_params = f"{focal_length_px},{width / 2},{height / 2},0"
    pycolmap.extract_features(database, image_dir, image_names=[p.name for p in images],
                              camera_mode=pycolmap.CameraMode.SINGLE, reader_options=reader,
                              extraction_options=extraction_options(cfg, threads), device=pycolmap.Device.cpu)
    times["extract_s"] = time.perf_counter() - start

    options = pycolmap.IncrementalPipelineOptions()
    options.num_threads = threads
    options.random_seed = options.mapper.random_seed = options.triangulation.random_seed = COLMAP_SEED
    options.mapper.init_min_num_inliers = INIT_MIN_INLIERS
    options.mapper.abs_pose_min_num_inliers = MIN_POSE_INLIERS
    options.min_model_size = 3
    if focal_length_px:
        options.ba_refine_focal_length = False
        options.mapper.abs_pose_refine_focal_length = False

    def match_and_map(matcher: str) -> dict:
        """Match the database's images by `matcher` (pairs already matched are kept) and map them afresh."""
        start = time.perf_counter()
        match_features(database, matcher, threads)
        times["match_s"] = times.get("match_s", 0.0) + time.perf_counter() - start
        start = time.perf_counter()
        shutil.rmtree(work / "sparse")
        (work / "sparse").mkdir()
        found = pycolmap.incremental_mapping(database, image_dir, work / "sparse", options)
        times["map_s"] = times.get("map_s", 0.0) + time.perf_counter() - start
        return found

    def enough(found: dict) -> bool:
        return bool(found) and max(m.num_reg_images() for m in found.values()) >= cfg.min_registered_fraction * len(
            images)

    matcher = cfg.matcher
    if matcher == "auto" and len(images) <= EXHAUSTIVE_MAX_IMAGES:
        matcher = "exhaustive"
    models = match_and_map("sequential" if matcher == "auto" else matcher)
    if matcher == "auto":
        matcher = "sequential"
        if not enough(models):
            log.warning("sequential matching registered too few of %d images (out of file order?): matching every "
                        "pair", len(images))
            models, matcher = match_and_map("exhaustive"), "sequential, then exhaustive"

    sizes = sorted((m.num_reg_images() for m in models.values()), reverse=True)
    summary = {"images": len(images), "matcher": matcher, "models": len(models), "model_sizes": sizes,
               **{k: round(v, 3) for k, v in times.items()}}
    if not models:
        raise SfMError(f"{image_dir}: COLMAP reconstructed no model from {len(images)} images "
                       "(too few matching features: textureless object and background, or too little overlap)",
                       summary)
    model = max(models.values(), key=lambda m: m.num_reg_images())
    registered = model.num_reg_images()
    summary.update(registered=registered, mean_reprojection_error_px=float(model.compute_mean_reprojection_error()),
                   points=model.num_points3D())
    log.info("sfm summary: %s", summary)
    if registered < cfg.min_registered_fraction * len(images):
        several = f"; {len(models)} disconnected models of {sizes} images" if len(models) > 1 else ""
        raise SfMError(f"{image_dir}: COLMAP registered {registered} of {len(images)} images, fewer than "
                       f"min_registered_fraction={cfg.min_registered_fraction}{several}", summary)
    if len(models) > 1:
        log.warning("%d disconnected models %s: using the largest; the other images get no camera", len(models), sizes)
    if summary["mean_reprojection_error_px"] > MAX_REPROJECTION_ERROR_PX:
        raise SfMError(f"{image_dir}: mean reprojection error {summary['mean_reprojection_error_px']:.2f} px "
                       f"exceeds max_reprojection_error_px={MAX_REPROJECTION_ERROR_PX}", summary)

    return model_contents(model, summary, len(images), cfg, image_dir)


def in_view_fraction(points: np.ndarray, cameras: list[Camera]) -> np.ndarray:
    """Fraction (N,) of the cameras whose image contains each point (in front, inside the frame)."""
    count = np.zeros(len(points))
    for cam in cameras:
        xy, depth = cam.project(points)
        count += (depth > 0) & (xy[:, 0] >= 0) & (xy[:, 0] < cam.width) & (xy[:, 1] >= 0) & (xy[:, 1] < cam.height)
    return count / max(len(cameras), 1)


def object_points(points: np.ndarray, cameras: list[Camera], fraction: float) -> np.ndarray:
    """Which sparse points are on the object: those most cameras have in view (a walk-around keeps the
    object in frame; the surroundings leave it) within the largest sphere around the point the
    cameras look at that every camera sees whole."""
    centre, radius = visible_sphere(cameras)
    near = np.linalg.norm(points - centre, axis=1) <= radius / 0.9
    return near & (in_view_fraction(points, cameras) >= fraction)


def off_centre_views(cameras: dict[str, Camera], rounds: int = 3) -> list[str]:
    """Views whose image does not contain the point the (other) cameras look at, found by
    alternating the least-squares centre of the optical axes and the views that see it."""
    keep = dict(cameras)
    for _ in range(rounds):
        if len(keep) < 3:
            break
        centre = axes_centre(list(keep.values()))
        inside = {}
        for name, cam in cameras.items():
            xy, depth = cam.project(centre[None])
            inside[name] = bool(depth[0] > 0 and 0 <= xy[0, 0] < cam.width and 0 <= xy[0, 1] < cam.height)
        keep = {n: c for n, c in cameras.items() if inside[n]}
    return sorted(n for n in cameras if n not in keep)


def up_direction(cameras: list[Camera]) -> np.ndarray:
    """Scene up: the normal of the plane through the camera centres (a ring), signed like the cameras'
    mean up vector; the mean up vector itself when the centres do not span a plane clearly."""
    centres = np.array([c.center for c in cameras])
    mean_up = np.mean([c.c2w[:3, 1] for c in cameras], axis=0)
    mean_up /= np.linalg.norm(mean_up)
    if len(cameras) < 3:
        return mean_up
    _, s, vt = np.linalg.svd(centres - centres.mean(0))
    if s[2] > 0.5 * s[1]:
        return mean_up
    normal = vt[2]
    return normal if normal @ mean_up >= 0 else -normal


def model_contents(model, summary: dict, images: int, cfg: SfMConfig, source: Path) -> SparseModel:
    """The cameras (views that do not look at the object dropped) and sparse points of a COLMAP reconstruction;
    too few consistent views is an SfMError naming `source`."""
    cameras = {}
    for image in model.images.values():
        if not image.has_pose:
            continue
        cam = model.cameras[image.camera_id]
        name = Path(image.name).stem
        fx, fy, cx, cy, lens = _intrinsics(cam)
        cameras[name] = colmap_to_camera(image.cam_from_world().matrix(), cam.width, cam.height, fx, fy, cx, cy, name,
                                         lens)
    lens = next(iter(cameras.values())).lens if cameras else None  # one camera for all views (CameraMode.SINGLE)
    summary["lens"] = lens.to_json() if lens else None
    rejected = off_centre_views(cameras) if REJECT_OFF_CENTRE else []
    if rejected:
        log.warning("dropping %d views that do not look at the object (misregistered): %s", len(rejected), rejected)
        cameras = {n: c for n, c in cameras.items() if n not in rejected}
    summary.update(rejected_views=rejected, registered=len(cameras))
    if len(cameras) < cfg.min_registered_fraction * images:
        raise SfMError(f"{source}: {len(cameras)} of {images} images registered consistently "
                       f"({len(rejected)} do not look at the object), fewer than "
                       f"min_registered_fraction={cfg.min_registered_fraction}", summary)
    xyz, rgb, on_object = sparse_points(model, cameras)
    summary["object_points"] = int(on_object.sum())
    return SparseModel(cameras, xyz, rgb, on_object, summary)


def sparse_points(model, cameras: dict[str, Camera]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A COLMAP reconstruction's points seen in at least MIN_TRACK_LENGTH images: (points (N, 3), colours (N, 3) in
    [0, 1], which are on the object under `cameras`, `object_points`)."""
    tracks = [(p.xyz, p.color, p.track.length()) for p in model.points3D.values()]
    xyz = np.array([t[0] for t in tracks], dtype=np.float64).reshape(-1, 3)
    rgb = np.array([t[1] for t in tracks], dtype=np.float64).reshape(-1, 3) / 255.0
    keep = np.array([t[2] >= MIN_TRACK_LENGTH for t in tracks], dtype=bool)
    on_object = object_points(xyz[keep], list(cameras.values()), OBJECT_VIEW_FRACTION) if keep.any() else keep[keep]
    return xyz[keep], rgb[keep], on_object


def read_model(folder: Path, cfg: SfMConfig | None = None) -> SparseModel:
    """A capture's own COLMAP model (text or binary: cameras, images, points3D), read with pycolmap as it is:
    its cameras and intrinsics as given, its sparse points kept."""
    import pycolmap

    cfg = cfg or SfMConfig()
    try:
        model = pycolmap.Reconstruction(str(folder))
    except (RuntimeError, ValueError):
        raise SfMError(f"{folder}: not a readable COLMAP model (cameras, images and points3D as .txt or .bin)") \
            from None
    summary = {"source": str(folder), "images": model.num_images(), "registered": model.num_reg_images(),
               "points": model.num_points3D(),
               "mean_reprojection_error_px": float(model.compute_mean_reprojection_error())}
    if model.num_reg_images() == 0:
        raise SfMError(f"{folder}: the COLMAP model has no registered image", summary)
    return model_contents(model, summary, model.num_images(), cfg, folder)


def similarity_to_dpi(model: SparseModel) -> tuple[float, np.ndarray, np.ndarray]:
    """(scale s, rotation R, centre c) of the map x -> s R (x - c) into dpi's normalised frame."""
    cameras = list(model.cameras.values())
    up = up_direction(cameras)
    forward = -cameras[0].c2w[:3, 2]
    forward = forward - (forward @ up) * up
    if np.linalg.norm(forward) < 1e-6:
        forward = np.cross(up, [1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else np.cross(up, [0.0, 0.0, 1.0])
    back = -forward / np.linalg.norm(forward)
    right = np.cross(up, back)
    rotation = np.stack([right, up, back])  # rows: new x, y, z axes in COLMAP coordinates
    pts = model.points[model.on_object]
    if len(pts) >= 20:
        local = pts @ rotation.T
        lo, hi = np.percentile(local, 2, axis=0), np.percentile(local, 98, axis=0)
        centre = rotation.T @ ((lo + hi) / 2)
        radius = np.percentile(np.linalg.norm(pts - centre, axis=1), 98)
    else:
        log.warning("only %d sparse points on the object: centring on the cameras' optical axes", len(pts))
        centre = axes_centre(cameras)
        radius = 0.25 * np.median([np.linalg.norm(c.center - centre) for c in cameras])
    return 1.0 / float(radius), rotation, centre


def transform_camera(camera: Camera, scale: float, rotation: np.ndarray, centre: np.ndarray) -> Camera:
    """A camera moved by the similarity x -> scale * rotation @ (x - centre)."""
    c2w = np.eye(4)
    c2w[:3, :3] = rotation @ camera.c2w[:3, :3]
    c2w[:3, 3] = scale * rotation @ (camera.c2w[:3, 3] - centre)
    return Camera(c2w, camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy, camera.name,
                  dict(camera.extras), camera.lens)


def normalise(model: SparseModel) -> SparseModel:
    """The model in dpi's frame: object at the origin with radius ~1, +Y up, first camera looking along -Z."""
    scale, rotation, centre = similarity_to_dpi(model)
    cameras = {n: transform_camera(c, scale, rotation, centre) for n, c in model.cameras.items()}
    points = scale * (model.points - centre) @ rotation.T
    summary = {**model.summary, "normalisation": {"scale": scale, "rotation": rotation.tolist(),
                                                  "centre": centre.tolist()}}
    return SparseModel(cameras, points, model.colors, model.on_object, summary)


def write_points_ply(path: str | Path, points: np.ndarray, colors: np.ndarray, on_object: np.ndarray) -> None:
    """Sparse points as an ASCII PLY (x, y, z, red, green, blue, object flag)."""
    from dpi.io.atomic import write_text

    lines = ["ply", "format ascii 1.0", f"element vertex {len(points)}", "property float x", "property float y",
             "property float z", "property uchar red", "property uchar green", "property uchar blue",
             "property uchar object", "end_header"]
    rgb = np.clip(np.round(colors * 255), 0, 255).astype(int)
    lines += [f"{p[0]:.6f} {p[1]:.6f} {p[2]:.6f} {c[0]} {c[1]} {c[2]} {int(o)}"
              for p, c, o in zip(points, rgb, on_object)]
    write_text(path, "\n".join(lines) + "\n")


def read_points_ply(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points, colours in [0, 1], object flags) from a file written by `write_points_ply`."""
    text = Path(path).read_text().split("end_header\n", 1)[1]
    data = np.loadtxt(text.splitlines(), ndmin=2) if text.strip() else np.zeros((0, 7))
    return data[:, :3], data[:, 3:6] / 255.0, data[:, 6].astype(bool)


def config_dict(cfg: SfMConfig) -> dict:
    """The settings as a plain dict (recorded in the summary)."""
    return asdict(cfg)
