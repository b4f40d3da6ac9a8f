"""A COLMAP text model of a capture's cameras, written by hand in COLMAP's documented text format (cameras.txt,
images.txt, points3D.txt), with points on the unit sphere seen by the cameras they project into."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from dpi.capture.cameras import Camera
from dpi.preprocess.sfm import CV_TO_GL


def write_text_model(folder: Path, cameras: dict[str, Camera], suffix: str = ".png", points: int = 200) -> None:
    """cameras.txt (one PINHOLE camera per view), images.txt and points3D.txt for `cameras` (dpi's convention)."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    xyz = rng.normal(size=(points, 3))
    xyz /= np.linalg.norm(xyz, axis=1, keepdims=True)
    observations: dict[int, list[tuple[int, int]]] = {p: [] for p in range(points)}
    cam_lines, image_lines = [], []
    for i, (name, cam) in enumerate(cameras.items(), start=1):
        cam_lines.append(f"{i} PINHOLE {cam.width} {cam.height} {cam.fx} {cam.fy} {cam.cx} {cam.cy}")
        w2c = np.linalg.inv(cam.c2w @ CV_TO_GL)
        qx, qy, qz, qw = Rotation.from_matrix(w2c[:3, :3]).as_quat()
        local = xyz @ w2c[:3, :3].T + w2c[:3, 3]
        uv = local[:, :2] / local[:, 2:] * [cam.fx, cam.fy] + [cam.cx, cam.cy]
        seen = (local[:, 2] > 0) & (uv >= 0).all(1) & (uv < [cam.width, cam.height]).all(1)
        obs = []
        for p in np.flatnonzero(seen):
            observations[p].append((i, len(obs)))
            obs.append(f"{uv[p, 0]} {uv[p, 1]} {p + 1}")
        t = w2c[:3, 3]
        image_lines += [f"{i} {qw} {qx} {qy} {qz} {t[0]} {t[1]} {t[2]} {i} {name}{suffix}", " ".join(obs)]
    point_lines = [f"{p + 1} {x} {y} {z} 128 128 128 0.5 " + " ".join(f"{i} {j}" for i, j in track)
                   for p, ((x, y, z), track) in enumerate(zip(xyz, observations.values())) if len(track) >= 2]
    (folder / "cameras.txt").write_text("\n".join(cam_lines) + "\n")
    (folder / "images.txt").write_text("\n".join(image_lines) + "\n")
    (folder / "points3D.txt").write_text("\n".join(point_lines) + "\n")
