"""Cameras: dpi's one convention and conversions to transforms.json and Mitsuba.

Inside dpi a camera is a camera-to-world 4x4 matrix in the OpenGL convention used by
transforms.json (nerfstudio / NeRF-synthetic): camera x right, y up, looking along -z; plus
pixel intrinsics (fx, fy, cx, cy) with the origin at the image's top-left corner. Mitsuba's
sensors look along +z with x pointing left, so `to_mitsuba` flips the x and z axes. A photo's lens
distortion (`Lens`, OpenCV's models as COLMAP and nerfstudio name them) is read here and removed from the
images once, at capture time (dpi.capture.undistort); every later stage sees pinhole cameras.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

GL_TO_MITSUBA = np.diag([-1.0, 1.0, -1.0, 1.0])
RIGID_TOLERANCE = 1e-3
"""max |R^T R - I| of a camera rotation (Mitsuba refuses scale factors from about 1.2e-3 on)"""
SQUARE_PIXEL_TOLERANCE = 1e-3
"""max |fx - fy| / fx: Mitsuba's perspective sensor has square pixels"""


PINHOLE_MODELS = ("PINHOLE", "SIMPLE_PINHOLE")
DISTORTED_MODELS = ("OPENCV", "FULL_OPENCV", "RADIAL", "SIMPLE_RADIAL")
"""pinhole projection plus OpenCV's polynomial distortion (k1, k2, k3 radial; p1, p2 tangential)"""
FISHEYE_MODELS = ("OPENCV_FISHEYE",)
"""OpenCV's fisheye (equidistant) projection with k1..k4"""
CAMERA_MODELS = PINHOLE_MODELS + DISTORTED_MODELS + FISHEYE_MODELS
DISTORTION_KEYS = ("k1", "k2", "k3", "k4", "p1", "p2")


@dataclass(frozen=True)
class Lens:
    """Lens distortion in OpenCV's models, on normalised image coordinates (so it survives resizing)."""

    fisheye: bool = False
    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0
    p1: float = 0.0
    p2: float = 0.0

    def coefficients(self) -> np.ndarray:
        """OpenCV's distortion vector: (k1, k2, k3, k4) for the fisheye model, else (k1, k2, p1, p2, k3)."""
        values = (self.k1, self.k2, self.k3, self.k4) if self.fisheye else (self.k1, self.k2, self.p1, self.p2, self.k3)
        return np.asarray(values, dtype=np.float64)

    def distort(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Normalised pinhole coordinates (x right, y down) as the lens images them (OpenCV's models)."""
        r2 = x * x + y * y
        if self.fisheye:
            r = np.sqrt(r2)
            theta = np.arctan(r)
            t2 = theta * theta
            scaled = theta * (1 + t2 * (self.k1 + t2 * (self.k2 + t2 * (self.k3 + t2 * self.k4))))
            factor = np.where(r > 1e-12, scaled / np.maximum(r, 1e-12), 1.0)
            return x * factor, y * factor
        radial = 1 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        return (x * radial + 2 * self.p1 * x * y + self.p2 * (r2 + 2 * x * x),
                y * radial + self.p1 * (r2 + 2 * y * y) + 2 * self.p2 * x * y)

    def to_json(self) -> dict:
        """transforms.json keys of this lens (camera_model and its non-zero coefficients)."""
        values = {k: getattr(self, k) for k in DISTORTION_KEYS if getattr(self, k)}
        return {"camera_model": FISHEYE_MODELS[0] if self.fisheye else "OPENCV", **values}


@dataclass
class Camera:
    """A camera: OpenGL camera-to-world matrix, pixel intrinsics, and the lens distortion of the photos it took
    (None: a pinhole)."""

    c2w: np.ndarray
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    name: str = ""
    extras: dict = field(default_factory=dict)
    lens: Lens | None = None

    @property
    def fov_x_deg(self) -> float:
        """Horizontal field of view in degrees."""
        return math.degrees(2 * math.atan(self.width / (2 * self.fx)))

    @property
    def center(self) -> np.ndarray:
        """Camera position in world space."""
        return self.c2w[:3, 3].copy()

    def resized(self, width: int, height: int) -> "Camera":
        """The same camera for an image resampled to width x height."""
        sx, sy = width / self.width, height / self.height
        return Camera(self.c2w.copy(), width, height, self.fx * sx, self.fy * sy, self.cx * sx, self.cy * sy,
                      self.name, dict(self.extras), self.lens)

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (N, 2) (x right, y down) and depth (N,) of world points (N, 3), through the lens."""
        w2c = np.linalg.inv(self.c2w)
        p = points @ w2c[:3, :3].T + w2c[:3, 3]
        depth = -p[:, 2]
        x, y = p[:, 0] / depth, -p[:, 1] / depth
        if self.lens is not None:
            x, y = self.lens.distort(x, y)
        return np.stack([self.fx * x + self.cx, self.fy * y + self.cy], axis=-1), depth


def pixel_rays(camera: Camera, supersample: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """World ray origins and unit directions (h, w, s*s, 3) through an s x s grid inside each pixel."""
    offsets = (np.arange(supersample) + 0.5) / supersample
    ys = (np.arange(camera.height)[:, None] + offsets[None, :]).reshape(-1)
    xs = (np.arange(camera.width)[:, None] + offsets[None, :]).reshape(-1)
    py, px = np.meshgrid(ys, xs, indexing="ij")
    d_cam = np.stack([(px - camera.cx) / camera.fx, -(py - camera.cy) / camera.fy, -np.ones_like(px)], -1)
    d = d_cam @ camera.c2w[:3, :3].T
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    s = supersample
    d = d.reshape(camera.height, s, camera.width, s, 3).transpose(0, 2, 1, 3, 4).reshape(camera.height, camera.width, s * s, 3)
    return np.broadcast_to(camera.c2w[:3, 3], d.shape).copy(), d


def centre_rays(camera: Camera) -> np.ndarray:
    """The rays through the pixel centres of `camera` as ray casters take them: (h * w, 6) float32 rows of origin and
    unit world direction, row-major over the image (the rays of `pixel_rays` at one sample a pixel)."""
    x = ((np.arange(camera.width, dtype=np.float32) + 0.5 - camera.cx) / camera.fx)[None, :]
    y = (-(np.arange(camera.height, dtype=np.float32) + 0.5 - camera.cy) / camera.fy)[:, None]
    rot = camera.c2w[:3, :3].astype(np.float32)
    d = x[..., None] * rot[:, 0] + y[..., None] * rot[:, 1] - rot[:, 2]
    d /= np.sqrt((d * d).sum(-1, keepdims=True))
    rays = np.empty((camera.height * camera.width, 6), np.float32)
    rays[:, :3] = camera.c2w[:3, 3]
    rays[:, 3:] = d.reshape(-1, 3)
    return rays


def look_at(origin, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """OpenGL camera-to-world matrix for a camera at `origin` looking at `target`."""
    origin, target, up = (np.asarray(v, dtype=np.float64) for v in (origin, target, up))
    back = origin - target
    back /= np.linalg.norm(back)
    right = np.cross(up, back)
    if np.linalg.norm(right) < 1e-9:
        raise ValueError("look_at: view direction is parallel to the up vector")
    right /= np.linalg.norm(right)
    true_up = np.cross(back, right)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = right, true_up, back, origin
    return c2w


def from_fov(c2w: np.ndarray, width: int, height: int, fov_x_deg: float, name: str = "") -> Camera:
    """Camera with square pixels, a centred principal point and the given horizontal FOV."""
    fx = width / (2 * math.tan(math.radians(fov_x_deg) / 2))
    return Camera(np.asarray(c2w, dtype=np.float64), width, height, fx, fx, width / 2, height / 2, name)


def camera_problem(camera: Camera) -> str | None:
    """Why a camera cannot be rendered, or None: its pose must be finite and rigid (an orthonormal
    rotation without reflection, last row 0 0 0 1), its size and focal lengths positive, its pixels square."""
    c2w = np.asarray(camera.c2w, dtype=np.float64)
    if c2w.shape != (4, 4) or not np.isfinite(c2w).all():
        return "camera-to-world matrix must be a finite 4x4 matrix"
    if np.abs(c2w[3] - [0, 0, 0, 1]).max() > RIGID_TOLERANCE:
        return f"camera-to-world matrix's last row must be [0, 0, 0, 1], got {c2w[3].tolist()}"
    rotation = c2w[:3, :3]
    error = float(np.abs(rotation.T @ rotation - np.eye(3)).max())
    if error > RIGID_TOLERANCE:
        return (f"camera-to-world rotation is not orthonormal (max |R^T R - I| = {error:.3g} > {RIGID_TOLERANCE:g}): "
                "the pose is scaled, sheared or singular, not rigid")
    if np.linalg.det(rotation) < 0:
        return "camera-to-world rotation is a reflection (determinant -1), not rigid"
    intrinsics = {"fx": camera.fx, "fy": camera.fy, "cx": camera.cx, "cy": camera.cy}
    if not all(math.isfinite(v) for v in intrinsics.values()):
        return f"intrinsics must be finite, got {intrinsics}"
    if camera.width < 1 or camera.height < 1:
        return f"image size must be positive, got {camera.width}x{camera.height}"
    if camera.fx <= 0 or camera.fy <= 0:
        return f"focal length must be positive (pixels), got fx={camera.fx:g}, fy={camera.fy:g}"
    if abs(camera.fx - camera.fy) > SQUARE_PIXEL_TOLERANCE * camera.fx:
        return (f"pixels must be square (fx == fy, as Mitsuba's perspective sensor), "
                f"got fx={camera.fx:g}, fy={camera.fy:g}")
    return None


def to_mitsuba(camera: Camera) -> dict:
    """Mitsuba `perspective` sensor dict (without film/sampler) for a camera; ValueError if `camera_problem`."""
    problem = camera_problem(camera)
    if problem:
        raise ValueError(f"camera {camera.name!r}: {problem}")
    import mitsuba as mi

    return {
        "type": "perspective",
        "fov": camera.fov_x_deg,
        "fov_axis": "x",
        "principal_point_offset_x": (camera.width / 2 - camera.cx) / camera.width,
        "principal_point_offset_y": (camera.height / 2 - camera.cy) / camera.height,
        "to_world": mi.ScalarTransform4f(camera.c2w @ GL_TO_MITSUBA),
    }


def from_mitsuba_matrix(to_world: np.ndarray) -> np.ndarray:
    """OpenGL camera-to-world matrix from a Mitsuba sensor's to_world matrix."""
    return np.asarray(to_world, dtype=np.float64) @ GL_TO_MITSUBA


def orbit(n: int, radius: float, elevations_deg: tuple[float, ...], target=(0.0, 0.0, 0.0),
          phase_deg: float = 0.0, arc_deg: float = 360.0) -> list[np.ndarray]:
    """`n` camera-to-world matrices on rings around `target` (+Y up), alternating elevations, spread
    evenly over all azimuths or, for `arc_deg` < 360, over an arc of that many degrees (ends included)."""
    poses = []
    step = 360.0 / n if arc_deg >= 360.0 else arc_deg / max(n - 1, 1)
    for i in range(n):
        azim = math.radians(phase_deg + step * i)
        elev = math.radians(elevations_deg[i % len(elevations_deg)])
        origin = np.asarray(target) + radius * np.array(
            [math.cos(elev) * math.sin(azim), math.sin(elev), math.cos(elev) * math.cos(azim)]
        )
        poses.append(look_at(origin, target))
    return poses


class TransformsError(ValueError):
    """A transforms.json value of the wrong type or missing; the message names the frame (or the top level) and key."""


NUMERIC_STRING_KEYS = ("fl_x", "fl_y", "cx", "cy", "w", "h", "camera_angle_x", *DISTORTION_KEYS)
"""keys nerfstudio reads through float() or int(), so a numeric string there is a number"""
BOOLEAN_FRAME_KEYS = ("held_out",)


def json_value(value: object) -> str:
    """A value as JSON writes it, with its JSON type: 'true (a boolean)', '"32" (a string)'."""
    kind = ("a boolean" if isinstance(value, bool) else "a number" if isinstance(value, (int, float))
            else "a string" if isinstance(value, str) else "null" if value is None
            else "a list" if isinstance(value, list) else "an object")
    text = json.dumps(value, default=str)
    return text if value is None else f"{text[:60]}{'...' if len(text) > 60 else ''} ({kind})"


def _where(data: dict, frame: dict, i: int, key: str) -> str:
    """Where a key's value comes from: 'frame 3 (images/r_3.png)' or 'top level'."""
    return f"frame {i} ({frame.get('file_path')})" if key in frame or key not in data else "top level"


def _number(data: dict, frame: dict, i: int, key: str, integer: bool = False) -> float:
    """The frame's (else the top level's) number `key`: a JSON number, or a numeric string where nerfstudio
    takes one (NUMERIC_STRING_KEYS); booleans and anything else are a TransformsError naming frame and key."""
    value = frame.get(key, data.get(key))
    expected = "an integer" if integer else "a number"
    if isinstance(value, str) and key in NUMERIC_STRING_KEYS:
        try:
            return int(value) if integer else float(value)
        except ValueError:
            pass
    elif isinstance(value, (int, float)) and not isinstance(value, bool) and (not integer or float(value).is_integer()):
        return int(value) if integer else float(value)
    raise TransformsError(f"{_where(data, frame, i, key)}: {key} must be {expected}, got {json_value(value)}")


def _matrix(frame: dict, i: int) -> np.ndarray:
    """A frame's transform_matrix: 4 rows of 4 JSON numbers, finite."""
    rows = frame["transform_matrix"]
    where = f"frame {i} ({frame.get('file_path')})"
    if not isinstance(rows, list) or len(rows) != 4 or not all(isinstance(r, list) and len(r) == 4 for r in rows):
        raise TransformsError(f"{where}: transform_matrix must be a 4x4 matrix (4 lists of 4 numbers), "
                              f"got {json_value(rows)}")
    for r, row in enumerate(rows):
        for c, value in enumerate(row):
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise TransformsError(f"{where}: transform_matrix[{r}][{c}] must be a number, got {json_value(value)}")
    c2w = np.asarray(rows, dtype=np.float64)
    if not np.isfinite(c2w).all():
        raise TransformsError(f"{where}: transform_matrix must be a finite 4x4 matrix")
    return c2w


def _extras(frame: dict, i: int) -> dict:
    """A frame's keys besides its path, pose, intrinsics and lens (a resized camera would carry stale ones), the
    booleans (held_out) checked."""
    for key in BOOLEAN_FRAME_KEYS:
        if key in frame and not isinstance(frame[key], bool):
            raise TransformsError(f"frame {i} ({frame.get('file_path')}): {key} must be a boolean (true or false), "
                                  f"got {json_value(frame[key])}")
    known = ("file_path", "transform_matrix", "camera_model", "w", "h", "fl_x", "fl_y", "cx", "cy", *DISTORTION_KEYS)
    return {k: frame[k] for k in frame if k not in known}


def _lens(data: dict, frame: dict, i: int) -> Lens | None:
    """The frame's (else the top level's) lens: its camera_model and distortion coefficients (None: a pinhole).

    A file with coefficients and no camera_model (instant-ngp) is OpenCV's pinhole model; a model dpi cannot
    undistort (equirectangular, ...) is a TransformsError naming it and the models read."""
    model = frame.get("camera_model", data.get("camera_model"))
    name = str(model).upper() if model is not None else None
    if name is not None and name not in CAMERA_MODELS:
        raise TransformsError(f"{_where(data, frame, i, 'camera_model')}: camera_model {json_value(model)} is not "
                              f"one dpi reads ({', '.join(CAMERA_MODELS)}); convert the images to one first")
    values = {k: _number(data, frame, i, k) for k in DISTORTION_KEYS if k in frame or k in data}
    fisheye = name in FISHEYE_MODELS
    if fisheye and ("p1" in values or "p2" in values):
        raise TransformsError(f"{_where(data, frame, i, 'p1')}: the fisheye model has no tangential terms p1, p2")
    if not fisheye and values.get("k4"):
        raise TransformsError(f"{_where(data, frame, i, 'k4')}: k4 belongs to OPENCV_FISHEYE, not {name or 'OPENCV'}")
    if name in PINHOLE_MODELS and any(values.values()):
        raise TransformsError(f"{_where(data, frame, i, 'camera_model')}: camera_model {name} has no distortion, "
                              f"yet the file gives {', '.join(k for k, v in values.items() if v)}")
    if not any(values.values()):
        return None
    return Lens(fisheye, **values)


def _frame_camera(data: dict, frame: dict, i: int, default_size: tuple[int, int] | None) -> Camera:
    """The camera of one frame, intrinsics from the frame, else the top level, else `default_size`."""
    if not isinstance(frame.get("file_path"), str):
        raise TransformsError(f"frame {i}: file_path must be a string, got {json_value(frame.get('file_path'))}")
    size = []
    for key, default in zip(("w", "h"), default_size or (None, None)):
        if key not in frame and key not in data and default is None:
            raise TransformsError(f"frame {i} ({frame['file_path']}): missing intrinsics: image size (w, h) unknown")
        size.append(_number(data, frame, i, key, integer=True) if key in frame or key in data else default)
    width, height = size
    if "fl_x" in frame or "fl_x" in data:
        fx = _number(data, frame, i, "fl_x")
        fy = _number(data, frame, i, "fl_y") if "fl_y" in frame or "fl_y" in data else fx
    elif "camera_angle_x" in frame or "camera_angle_x" in data:
        angle = _number(data, frame, i, "camera_angle_x")
        if not 0 < angle < math.pi:
            raise TransformsError(f"{_where(data, frame, i, 'camera_angle_x')}: camera_angle_x must be in (0, pi) "
                                  f"radians, got {angle!r}")
        fx = fy = width / (2 * math.tan(angle / 2))
    else:
        raise TransformsError(f"frame {i} ({frame['file_path']}): missing intrinsics: no focal length "
                              "(fl_x or camera_angle_x)")
    cx = _number(data, frame, i, "cx") if "cx" in frame or "cx" in data else width / 2
    cy = _number(data, frame, i, "cy") if "cy" in frame or "cy" in data else height / 2
    return Camera(_matrix(frame, i), width, height, fx, fy, cx, cy, frame["file_path"], _extras(frame, i),
                  _lens(data, frame, i))


def read_transforms(data: dict, default_size: tuple[int, int] | None = None) -> list[tuple[str, Camera]]:
    """(file_path, Camera) per frame of a parsed transforms.json (nerfstudio or NeRF-synthetic).

    Intrinsics come from the frame, else the file's top level; NeRF-synthetic files give only
    `camera_angle_x`, so the image size must then come from `default_size` (width, height). Values are
    typed strictly (a TransformsError names the frame, the key, the value and the type expected): numbers
    are JSON numbers, or numeric strings for the intrinsics nerfstudio reads with float()/int(); held_out
    is a boolean.
    """
    cameras = [_frame_camera(data, frame, i, default_size) for i, frame in enumerate(data["frames"])]
    return [(camera.name, camera) for camera in cameras]


def read_cameras(path: str | Path) -> dict[str, Camera]:
    """view name -> Camera from a transforms.json file (file paths "images/{view}.png" or "{view}")."""
    cameras = {}
    for file_path, camera in read_transforms(json.loads(Path(path).read_text())):
        camera.name = Path(file_path).stem
        cameras[camera.name] = camera
    return cameras


def write_transforms(frames: list[tuple[str, Camera]]) -> dict:
    """transforms.json content (nerfstudio convention, intrinsics per frame) for (file_path, Camera)."""
    out = []
    for path, cam in frames:
        out.append({
            "file_path": path,
            "transform_matrix": cam.c2w.tolist(),
            "w": cam.width, "h": cam.height,
            "fl_x": cam.fx, "fl_y": cam.fy, "cx": cam.cx, "cy": cam.cy,
            **(cam.lens.to_json() if cam.lens else {}),
            **cam.extras,
        })
    return {"camera_model": "OPENCV", "frames": out}
