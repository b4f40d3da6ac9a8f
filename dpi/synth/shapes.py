"""Procedural meshes with UV atlases for synthetic captures.

The shapes are parametric surfaces sampled on a (rows+1) x (cols+1) grid whose seam vertices are
duplicated, so their UVs are the surface parameters themselves:
- `blob`: a sphere with smooth radial bumps (convex-ish, no self-occlusion to speak of);
- `bumpy_torus`: a torus with bumps (concave, self-occluding, a hole);
- `bowl`: a thick-walled bowl on a flat foot (a cavity silhouettes cannot see into, a flat base);
- `blob_on_plate`: the blob standing on a flat round plate, the plate's UVs in their own band of the atlas
  (BASE_V and up) so that it can carry a second material (dpi.synth.capture: a rough body on a glossy base).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

SHAPES = ("blob", "bumpy_torus", "bowl", "blob_on_plate")
BASE_V = 0.65
"""v from which a shape's base (the plate of blob_on_plate) lies in its UVs; the body keeps v below BODY_V"""
BODY_V = 0.6


@dataclass
class TriangleMesh:
    """Vertices (V, 3), triangle indices (F, 3) and per-vertex UVs (V, 2) in [0, 1]."""

    vertices: np.ndarray
    faces: np.ndarray
    uvs: np.ndarray


def _bumps(u: np.ndarray, v: np.ndarray, rng: np.random.Generator, amplitude: float, terms: int = 4) -> np.ndarray:
    """Smooth periodic displacement field over (u, v) in [0, 1]^2 (periodic in u)."""
    field = np.zeros_like(u)
    for _ in range(terms):
        fu, fv = rng.integers(1, 4), rng.integers(1, 4)
        pu, pv = rng.uniform(0, 2 * np.pi, 2)
        field += np.sin(2 * np.pi * fu * u + pu) * np.sin(np.pi * fv * v + pv)
    return amplitude * field / terms


def _grid_faces(rows: int, cols: int) -> np.ndarray:
    """Two triangles per quad of a (rows+1) x (cols+1) vertex grid, counter-clockwise seen from outside."""
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    a = r * (cols + 1) + c
    b, d = a + 1, a + cols + 1
    e = d + 1
    return np.concatenate([np.stack([a, d, b], -1).reshape(-1, 3), np.stack([b, d, e], -1).reshape(-1, 3)])


def _drop_degenerate(mesh: TriangleMesh) -> TriangleMesh:
    """Remove zero-area triangles (they appear at the poles of a sphere grid)."""
    v = mesh.vertices[mesh.faces]
    area = np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=-1)
    return TriangleMesh(mesh.vertices, mesh.faces[area > 1e-12], mesh.uvs)


def blob(resolution: int = 48, bump: float = 0.12, seed: int = 0) -> TriangleMesh:
    """Bumpy unit sphere; u = azimuth / 2pi, v = polar angle / pi (v=0 at the top)."""
    rng = np.random.default_rng(seed)
    rows, cols = resolution, 2 * resolution
    v, u = np.meshgrid(np.linspace(0, 1, rows + 1), np.linspace(0, 1, cols + 1), indexing="ij")
    theta, phi = np.pi * v, 2 * np.pi * u
    radius = 1.0 + _bumps(u, v, rng, bump) * np.sin(theta)
    pos = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta), np.sin(theta) * np.cos(phi)], -1) * radius[..., None]
    uvs = np.stack([u, 1.0 - v], -1)
    return _drop_degenerate(TriangleMesh(pos.reshape(-1, 3), _grid_faces(rows, cols), uvs.reshape(-1, 2)))


def bumpy_torus(resolution: int = 48, major: float = 0.75, minor: float = 0.35, bump: float = 0.25,
                seed: int = 0) -> TriangleMesh:
    """Torus around +Y with a bumpy tube, tilted so its hole and inner side are seen and self-occlude."""
    rng = np.random.default_rng(seed)
    rows, cols = resolution, 2 * resolution
    v, u = np.meshgrid(np.linspace(0, 1, rows + 1), np.linspace(0, 1, cols + 1), indexing="ij")
    phi, psi = 2 * np.pi * u, 2 * np.pi * v
    r = minor * (1.0 + _bumps(u, v, rng, bump))
    ring = major + r * np.cos(psi)
    pos = np.stack([ring * np.sin(phi), r * np.sin(psi), ring * np.cos(phi)], -1)
    tilt = np.radians(25.0)
    rot = np.array([[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]])
    pos = pos @ rot.T
    uvs = np.stack([u, 1.0 - v], -1)
    return TriangleMesh(pos.reshape(-1, 3), _grid_faces(rows, cols)[:, ::-1].copy(), uvs.reshape(-1, 2))


BOWL_PROFILE = np.array([[0.0, -0.5], [0.5, -0.5], [0.55, -0.38], [1.0, 0.42], [0.98, 0.5], [0.88, 0.5],
                         [0.48, -0.28], [0.0, -0.3]])
"""(radius, height) of the bowl's cross-section, from the foot's centre out, up the outer wall, over the
rim and down the inner wall to the cavity's centre"""


def bowl(resolution: int = 48) -> TriangleMesh:
    """A bowl revolved about +Y from BOWL_PROFILE (resampled evenly by arc length); u = azimuth, v = profile."""
    rows, cols = 2 * resolution, 2 * resolution
    steps = np.linalg.norm(np.diff(BOWL_PROFILE, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(steps)]) / steps.sum()
    t = np.linspace(0, 1, rows + 1)
    radius, height = np.interp(t, arc, BOWL_PROFILE[:, 0]), np.interp(t, arc, BOWL_PROFILE[:, 1])
    v, u = np.meshgrid(t, np.linspace(0, 1, cols + 1), indexing="ij")
    phi = 2 * np.pi * u
    pos = np.stack([radius[:, None] * np.sin(phi), np.broadcast_to(height[:, None], phi.shape),
                    radius[:, None] * np.cos(phi)], -1)
    uvs = np.stack([u, 1.0 - v], -1)
    return _drop_degenerate(TriangleMesh(pos.reshape(-1, 3), _grid_faces(rows, cols)[:, ::-1].copy(), uvs.reshape(-1, 2)))


PLATE_RADIUS = 1.3
"""radius of blob_on_plate's plate, twice the blob's"""


def plate(resolution: int = 48, radius: float = PLATE_RADIUS, height: float = -0.95) -> TriangleMesh:
    """A flat disc facing +Y at `height`; u = azimuth, v from BASE_V at the centre to 1 at the rim."""
    rows, cols = resolution // 2, 2 * resolution
    t, u = np.meshgrid(np.linspace(0, 1, rows + 1), np.linspace(0, 1, cols + 1), indexing="ij")
    phi = 2 * np.pi * u
    pos = np.stack([radius * t * np.sin(phi), np.full_like(t, height), radius * t * np.cos(phi)], -1)
    uvs = np.stack([u, BASE_V + (1.0 - BASE_V) * t], -1)
    mesh = _drop_degenerate(TriangleMesh(pos.reshape(-1, 3), _grid_faces(rows, cols), uvs.reshape(-1, 2)))
    v = mesh.vertices[mesh.faces]
    if np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])[:, 1].mean() < 0:  # face up
        mesh.faces = mesh.faces[:, ::-1].copy()
    return mesh


def blob_on_plate(resolution: int = 48, seed: int = 0) -> TriangleMesh:
    """The blob (its UVs squeezed below BODY_V) standing on `plate` (UVs from BASE_V up)."""
    body, base = blob(resolution, seed=seed), plate(resolution)
    body_uvs = body.uvs * [1.0, BODY_V]
    return TriangleMesh(np.concatenate([body.vertices, base.vertices]),
                        np.concatenate([body.faces, base.faces + len(body.vertices)]),
                        np.concatenate([body_uvs, base.uvs]))


def make_shape(name: str, resolution: int = 48, seed: int = 0) -> TriangleMesh:
    """Build one of SHAPES by name."""
    if name == "blob":
        return blob(resolution, seed=seed)
    if name == "bumpy_torus":
        return bumpy_torus(resolution, seed=seed)
    if name == "bowl":
        return bowl(resolution)
    if name == "blob_on_plate":
        return blob_on_plate(resolution, seed=seed)
    raise ValueError(f"unknown shape {name!r}; choose from {', '.join(SHAPES)}")


def write_ply(path: str | Path, mesh: TriangleMesh) -> None:
    """Write a PLY with per-vertex UVs through Mitsuba's own writer, so Mitsuba reads it back exactly."""
    from dpi.io.atomic import atomic_path
    from dpi.render import backend

    mi = backend.mitsuba()
    m = mi.Mesh("mesh", len(mesh.vertices), len(mesh.faces), has_vertex_normals=False, has_vertex_texcoords=True)
    params = mi.traverse(m)
    params["vertex_positions"] = mi.Float(mesh.vertices.astype(np.float32).ravel())
    params["faces"] = mi.UInt32(mesh.faces.astype(np.uint32).ravel())
    params["vertex_texcoords"] = mi.Float(mesh.uvs.astype(np.float32).ravel())
    params.update()
    with atomic_path(path) as tmp:
        m.write_ply(str(tmp))
