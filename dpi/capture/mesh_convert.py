"""A given mesh in a format Mitsuba does not read (glTF: .glb, .gltf) converted once, at capture time, to a PLY
beside capture.json, with its UVs and its scene graph's transforms applied (trimesh), so the later stages see a
PLY like any other mesh."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from dpi.capture.meshes import GLTF_SUFFIXES
from dpi.capture.model import Capture
from dpi.io.atomic import atomic_path


def renderable_mesh(capture: Capture, ply: str | Path) -> Capture:
    """The capture with a glTF mesh replaced by its conversion to `ply` (rewritten when the source is newer);
    itself when its mesh is already PLY or OBJ, or it has none."""
    import trimesh

    if capture.mesh is None or capture.mesh.suffix.lower() not in GLTF_SUFFIXES:
        return capture
    ply = Path(ply)
    if not ply.is_file() or ply.stat().st_mtime_ns < capture.mesh.stat().st_mtime_ns:
        mesh = trimesh.load(capture.mesh, force="mesh", process=False)
        ply.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(ply) as tmp:
            mesh.export(tmp, file_type="ply")
    return replace(capture, mesh=ply)
