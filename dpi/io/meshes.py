"""Mesh files without UVs: what the geometry stage derives and a synthetic capture gives as a scanner would."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dpi.io.atomic import atomic_path


def write_mesh_ply(path: str | Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    """A mesh without UVs as a binary PLY (written by trimesh, atomically)."""
    import trimesh

    with atomic_path(path) as tmp:
        trimesh.Trimesh(vertices, faces, process=False).export(tmp, file_type="ply")
