"""Accuracy of derived inputs against ground truth: camera poses and surfaces (masks: dpi.capture.consistency.mask_iou).

Poses from structure from motion live in their own frame, so they are compared after the
similarity (Umeyama) that best maps their camera centres onto the true ones. Surfaces are
compared by the symmetric Chamfer distance between points sampled uniformly on both meshes,
as a fraction of the true mesh's bounding-box diagonal. The masks' confidence is judged against the masks' true
IoU (`flag_counts`).
"""

from __future__ import annotations

import numpy as np

from dpi.capture.cameras import Camera


def umeyama(source: np.ndarray, target: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(s, R, t) minimising sum |s R x_i + t - y_i|^2 for points x = source, y = target (N, 3)."""
    mu_x, mu_y = source.mean(0), target.mean(0)
    x, y = source - mu_x, target - mu_y
    cov = y.T @ x / len(source)
    u, d, vt = np.linalg.svd(cov)
    sign = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        sign[2, 2] = -1
    rotation = u @ sign @ vt
    scale = float(np.trace(np.diag(d) @ sign) / x.var(0).sum())
    return scale, rotation, mu_y - scale * rotation @ mu_x


def pose_errors(estimated: dict[str, Camera], truth: dict[str, Camera]) -> dict[str, float]:
    """Camera centre and rotation errors of the views in both sets, after Umeyama alignment.

    Centre errors are fractions of the true cameras' mean distance to their centroid; rotation
    errors are degrees; `focal_error` is the mean relative focal-length error.
    """
    names = [n for n in truth if n in estimated]
    est = np.array([estimated[n].center for n in names])
    true = np.array([truth[n].center for n in names])
    s, r, t = umeyama(est, true)
    aligned = est @ (s * r).T + t
    spread = np.linalg.norm(true - true.mean(0), axis=1).mean()
    centre = np.linalg.norm(aligned - true, axis=1) / spread
    angles = []
    for n in names:
        rel = truth[n].c2w[:3, :3].T @ r @ estimated[n].c2w[:3, :3]
        angles.append(np.degrees(np.arccos(np.clip((np.trace(rel) - 1) / 2, -1.0, 1.0))))
    focal = [abs(estimated[n].fx / truth[n].fx - 1) for n in names]
    return {"views": len(names), "centre_error_mean": float(centre.mean()), "centre_error_max": float(centre.max()),
            "rotation_error_deg_mean": float(np.mean(angles)), "rotation_error_deg_max": float(np.max(angles)),
            "focal_error_mean": float(np.mean(focal))}


def sample_surface(vertices: np.ndarray, faces: np.ndarray, count: int, seed: int = 0) -> np.ndarray:
    """`count` points uniformly distributed (by area) on a triangle mesh."""
    rng = np.random.default_rng(seed)
    tri = vertices[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    pick = rng.choice(len(faces), size=count, p=area / area.sum())
    a, b = rng.random((2, count, 1))
    flip = a + b > 1
    a, b = np.where(flip, 1 - a, a), np.where(flip, 1 - b, b)
    t = tri[pick]
    return t[:, 0] + a * (t[:, 1] - t[:, 0]) + b * (t[:, 2] - t[:, 0])


def chamfer(vertices_a: np.ndarray, faces_a: np.ndarray, vertices_b: np.ndarray, faces_b: np.ndarray,
            samples: int = 50_000, seed: int = 0) -> dict[str, float]:
    """Symmetric Chamfer distance (mean of both directions' mean nearest-point distances) between
    meshes a (estimate) and b (truth), absolute and as a fraction of b's bounding-box diagonal."""
    from scipy.spatial import cKDTree

    pa = sample_surface(vertices_a, faces_a, samples, seed)
    pb = sample_surface(vertices_b, faces_b, samples, seed + 1)
    d_ab = cKDTree(pb).query(pa)[0]
    d_ba = cKDTree(pa).query(pb)[0]
    value = 0.5 * (d_ab.mean() + d_ba.mean())
    diagonal = float(np.linalg.norm(vertices_b.max(0) - vertices_b.min(0)))
    return {"chamfer": float(value), "chamfer_rel": float(value / diagonal),
            "accuracy_p95_rel": float(np.percentile(d_ab, 95) / diagonal),
            "completeness_p95_rel": float(np.percentile(d_ba, 95) / diagonal)}


def align_mesh(vertices: np.ndarray, estimated: dict[str, Camera], truth: dict[str, Camera]) -> np.ndarray:
    """Vertices of a mesh built in the estimated cameras' frame, moved into the true cameras' frame."""
    names = [n for n in truth if n in estimated]
    s, r, t = umeyama(np.array([estimated[n].center for n in names]), np.array([truth[n].center for n in names]))
    return vertices @ (s * r).T + t


def flag_counts(ious: list[float], flagged: list[bool]) -> dict[str, int]:
    """How the masks' witnesses judged views whose true IoU is known: views under 0.8 IoU and how many of them were
    flagged, views over 0.9 IoU that were flagged (a truthful confidence flags all of the first, few of the last)."""
    below = [f for iou, f in zip(ious, flagged) if iou < 0.8]
    return {"masks_below_08": len(below), "flagged_below_08": sum(below),
            "flagged_above_09": sum(f for iou, f in zip(ious, flagged) if iou > 0.9)}
