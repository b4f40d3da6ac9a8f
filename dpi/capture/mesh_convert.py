"""A given mesh made renderable once, at capture time: a format Mitsuba does not read (glTF: .glb, .gltf) converted
to a PLY beside capture.json, with its UVs and its scene graph's transforms applied (trimesh), and a mesh whose faces
the given cameras see from behind (wound inwards: it would render dark) turned outwards in that PLY, so the later
stages see a PLY like any other mesh."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from dpi.capture.meshes import GLTF_SUFFIXES
from dpi.capture.model import Capture
from dpi.capture.consistency import back_facing_fraction
from dpi.io.atomic import atomic_path

BACK_FACING = 0.5
"""a mesh of which the cameras see more than this fraction from behind is turned outwards"""


def faces_inwards(capture: Capture, mesh) -> bool:
    """Whether the capture's given cameras see the mesh mostly from behind (False without given cameras)."""
    cameras = [v.camera for v in capture.views if v.camera is not None]
    if capture.provenance["cameras"] != "given" or not cameras:
        return False
    return back_facing_fraction(mesh.vertices, mesh.faces, cameras) > BACK_FACING


def renderable_mesh(capture: Capture, ply: str | Path) -> Capture:
    """The capture with a glTF mesh, or a mesh wound inwards, replaced by its renderable copy `ply` (rewritten when
    the source is newer); itself when its mesh is already a PLY or OBJ facing out, or it has none."""
    import trimesh

    if capture.mesh is None:
        return capture
    ply = Path(ply)
    if ply.is_file() and ply.stat().st_mtime_ns >= capture.mesh.stat().st_mtime_ns:
        return replace(capture, mesh=ply)
    mesh = trimesh.load(capture.mesh, force="mesh", process=False)
    inwards = faces_inwards(capture, mesh)
    if capture.mesh.suffix.lower() not in GLTF_SUFFIXES and not inwards:
        return capture
    if inwards:
        print(f"{capture.mesh}: the cameras see its faces from behind (wound inwards); turned outwards in {ply}",
              flush=True)
        mesh.invert()
    ply.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(ply) as tmp:
        mesh.export(tmp, file_type="ply")
    return replace(capture, mesh=ply)
