"""Pinhole cameras: dpi's one convention and conversions to transforms.json and Mitsuba.

Inside dpi a camera is a camera-to-world 4x4 matrix in the OpenGL convention used by
transforms.json (nerfstudio / NeRF-synthetic): camera x right, y up, looking along -z; plus
pixel intrinsics (fx, fy, cx, cy) with the origin at the image's top-left corner. Mitsuba's
sensors look along +z with x pointing left, so `to_mitsuba` flips the x and z axes.
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


@dataclass
class Camera:
    """A pinhole camera: OpenGL camera-to-world matrix and pixel intrinsics."""

    c2w: np.ndarray
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    name: str = ""
    extras: dict = field(default_factory=dict)

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
                      self.name, dict(self.extras))

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (N, 2) (x right, y down) and depth (N,) of world points (N, 3)."""
        w2c = np.linalg.inv(self.c2w)
        p = points @ w2c[:3, :3].T + w2c[:3, 3]
        depth = -p[:, 2]
        x = self.fx * p[:, 0] / depth + self.cx
        y = -self.fy * p[:, 1] / depth + self.cy
        return np.stack([x, y], axis=-1), depth


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


def read_transforms(data: dict, default_size: tuple[int, int] | None = None) -> list[tuple[str, Camera]]:
    """(file_path, Camera) per frame of a parsed transforms.json (nerfstudio or NeRF-synthetic).

    Intrinsics come from the frame, else the file's top level; NeRF-synthetic files give only
    `camera_angle_x`, so the image size must then come from `default_size` (width, height).
    """
    out = []
    for i, frame in enumerate(data["frames"]):
        info = {**data, **frame}
        width = info.get("w", default_size[0] if default_size else None)
        height = info.get("h", default_size[1] if default_size else None)
        if width is None or height is None:
            raise KeyError(f"frame {i}: image size (w, h) unknown")
        if "fl_x" in info:
            fx = float(info["fl_x"])
            fy = float(info.get("fl_y", fx))
        elif "camera_angle_x" in info:
            angle = float(info["camera_angle_x"])
            if not 0 < angle < math.pi:
                raise ValueError(f"frame {i}: camera_angle_x must be in (0, pi) radians, got {angle!r}")
            fx = fy = float(width) / (2 * math.tan(angle / 2))
        else:
            raise KeyError(f"frame {i}: no focal length (fl_x or camera_angle_x)")
        c2w = np.asarray(frame["transform_matrix"], dtype=np.float64)
        if c2w.shape != (4, 4) or not np.isfinite(c2w).all():
            raise ValueError(f"frame {i}: transform_matrix must be a finite 4x4 matrix")
        cx = float(info.get("cx", width / 2))
        cy = float(info.get("cy", height / 2))
        extras = {k: frame[k] for k in frame if k not in ("file_path", "transform_matrix")}
        out.append((str(frame["file_path"]), Camera(c2w, int(width), int(height), fx, fy, cx, cy,
                                                    str(frame["file_path"]), extras)))
    return out


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
            **cam.extras,
        })
    return {"camera_model": "OPENCV", "frames": out}
