"""transforms.json (nerfstudio, NeRF-synthetic, instant-ngp): cameras matched to the images by name, and per-frame
masks."""

from __future__ import annotations

from pathlib import Path, PurePosixPath

from dpi.capture.cameras import Camera, TransformsError, camera_problem, read_transforms
from dpi.capture.folder import view_name
from dpi.capture.model import CaptureError, inside_capture
from dpi.io.images import IMAGE_SUFFIXES
from dpi.io.structured import StructuredFileError, read_json

ASPECT_TOLERANCE = 1e-3


def fit_camera(source: Path, camera: Camera, size: tuple[int, int], name: str) -> Camera:
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


def frame_name(file_path: str) -> str:
    """View name a transforms.json file_path refers to ("./images/r_0.png", "r_0" -> "r_0")."""
    name = PurePosixPath(str(file_path).replace("\\", "/")).name
    return view_name(Path(name).stem if Path(name).suffix.lower() in IMAGE_SUFFIXES else name)


def read_transforms_json(path: Path) -> dict:
    """A parsed transforms.json, checked to hold a 'frames' list of frames with a file path and a pose."""
    inside_capture(path.parent, path, "the camera file")
    try:
        data = read_json(path)
    except StructuredFileError as exc:
        raise CaptureError(str(exc)) from None
    if not isinstance(data, dict) or not isinstance(data.get("frames"), list):
        raise CaptureError(f"{path}: missing 'frames' list")
    for i, frame in enumerate(data["frames"]):
        if not isinstance(frame, dict) or "file_path" not in frame or "transform_matrix" not in frame:
            raise CaptureError(f"{path}: frame {i} needs 'file_path' and 'transform_matrix'")
    return data


def transforms_cameras(path: Path, data: dict, names: list[str], size: tuple[int, int]) -> dict[str, Camera]:
    """view name -> camera from transforms.json (`data`, parsed), checking it covers exactly the images."""
    try:
        frames = read_transforms(data, default_size=size)
    except TransformsError as exc:
        raise CaptureError(f"{path}: {exc}") from exc
    cameras: dict[str, Camera] = {}
    unmatched = []
    for file_path, camera in frames:
        name = frame_name(file_path)
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
    return {n: fit_camera(path, cameras[n], size, n) for n in names}


def frame_masks(path: Path, data: dict) -> dict[str, Path] | None:
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
        masks[frame_name(frame["file_path"])] = inside_capture(path.parent, path.parent / frame["mask_path"],
                                                               f"the mask_path of frame {frame['file_path']!r}")
    return masks


def names_masks(path: Path) -> bool:
    """Whether a transforms.json exists and a frame of it names a `mask_path` (a broken file: False; load_capture
    names its problem)."""
    try:
        return path.is_file() and any("mask_path" in f for f in read_json(path).get("frames", []))
    except (StructuredFileError, AttributeError, TypeError):
        return False
