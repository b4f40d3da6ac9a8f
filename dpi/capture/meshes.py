"""The given mesh: mesh.ply / .obj / .glb / .gltf or scene.xml's shape, checked to load with faces, and whether it
carries UVs."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from dpi.capture.folder import named_files
from dpi.capture.mitsuba_xml import MitsubaXMLError, read_mesh_shapes
from dpi.capture.model import CaptureError, inside_capture

MESH_NAMES = ("mesh.ply", "mesh.obj", "mesh.glb", "mesh.gltf")
"""matched case-insensitively (mesh.PLY), as image suffixes are"""


GLTF_SUFFIXES = (".glb", ".gltf")
"""mesh formats Mitsuba does not read: the capture stage converts them to PLY (dpi.capture.mesh_convert)"""


PLY_UV_PAIRS = (("u", "v"), ("s", "t"), ("texture_u", "texture_v"), ("texture_s", "texture_t"))


PLY_HEADER_BYTES = 1 << 16


TRUE_SURFACE = "mesh.ply"
"""the true surface with the UVs gt/'s textures belong to (gt/mesh.ply), where the capture's own mesh is not it"""


def mesh_file(root: Path, options: dict) -> Path | None:
    """The given mesh: mesh.ply / .obj / .glb / .gltf (any case), else scene.xml's mesh shape (the one named `object`
    if several)."""
    given = named_files(root, MESH_NAMES)
    if len(given) > 1:
        raise CaptureError(f"{given[1]}: ambiguous mesh, {given[0].name} is also given")
    if given:
        inside_capture(root, given[0], "the mesh")
        return given[0]
    scene = root / "scene.xml"
    if not scene.is_file():
        return None
    try:
        shapes = read_mesh_shapes(scene)
    except MitsubaXMLError as exc:
        raise CaptureError(str(exc)) from exc
    if len(shapes) > 1:
        chosen = [s for s in shapes if options.get("object") in (s.id, s.filename.stem)]
        if len(chosen) != 1:
            raise CaptureError(f"{scene}: {len(shapes)} mesh shapes ({', '.join(s.filename.name for s in shapes)}); "
                               f"name the object's shape id or file stem with `object` in scene.yaml")
        shapes = chosen
    return inside_capture(root, shapes[0].filename, f"the mesh of {scene.name}") if shapes else None


def ply_vertex_properties(path: Path) -> set[str]:
    """Names of the vertex properties in a PLY header (empty if it is not a PLY file)."""
    with open(path, "rb") as f:
        head = f.read(PLY_HEADER_BYTES)
    if not head.startswith(b"ply"):
        return set()
    names, in_vertex = set(), False
    for line in head.split(b"end_header")[0].decode("ascii", "replace").splitlines():
        words = line.split()
        if words[:1] == ["element"]:
            in_vertex = words[1:2] == ["vertex"]
        elif words[:1] == ["property"] and in_vertex:
            names.add(words[-1])
    return names


def mesh_has_uv(path: str | os.PathLike) -> bool:
    """Whether a PLY (u/v, s/t, texture_u/v vertex properties), OBJ (`vt` lines) or glTF (TEXCOORD_0, through
    trimesh) mesh carries UVs."""
    path = Path(path)
    if path.suffix.lower() in GLTF_SUFFIXES:
        import trimesh

        mesh = trimesh.load(path, force="mesh", process=False)
        return getattr(mesh.visual, "uv", None) is not None and len(mesh.visual.uv) == len(mesh.vertices)
    if path.suffix.lower() == ".ply":
        names = ply_vertex_properties(path)
        return any(u in names and v in names for u, v in PLY_UV_PAIRS)
    with open(path, "rb") as f:
        return any(line[:3] in (b"vt ", b"vt\t") for line in f)


def check_mesh(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's vertices and faces, failing unless the file loads with trimesh, has faces indexing its
    vertices, and finite vertices and UVs."""
    import trimesh

    if not path.is_file():
        raise CaptureError(f"{path}: mesh file does not exist")
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many exception types for bad files
        raise CaptureError(f"{path}: unreadable mesh (trimesh: {type(exc).__name__})") from None
    if len(getattr(mesh, "faces", [])) == 0:
        raise CaptureError(f"{path}: mesh has no faces")
    bad = int((~np.isfinite(mesh.vertices)).any(axis=1).sum())
    if bad:
        raise CaptureError(f"{path}: {bad} of {len(mesh.vertices)} mesh vertices have NaN or Inf coordinates")
    if mesh.faces.min() < 0 or mesh.faces.max() >= len(mesh.vertices):
        raise CaptureError(f"{path}: faces index vertices outside 0..{len(mesh.vertices) - 1}")
    uv = getattr(mesh.visual, "uv", None)
    if uv is not None:
        problem = uv_problem(np.asarray(uv, np.float64), np.asarray(mesh.faces), np.asarray(mesh.area_faces))
        if problem:
            raise CaptureError(f"{path}: {problem}")
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


UV_SLACK = 1e-4
"""how far outside [0, 1] a UV may lie (rounding of a written atlas)"""
UNMAPPED_SHARE = 0.01
"""largest share of the surface's area whose faces have no area in the atlas (a few degenerate faces are common)"""


def uv_problem(uv: np.ndarray, faces: np.ndarray, areas: np.ndarray) -> str | None:
    """Why given UVs (n, 2) cannot carry dpi's textures (None: they can): not finite, outside the unit square the
    textures cover, collapsed to a point or a line, or leaving part of the surface without texels."""
    if not np.isfinite(uv).all():
        return "mesh UVs contain NaN or Inf values"
    outside = int(((uv < -UV_SLACK) | (uv > 1 + UV_SLACK)).any(axis=1).sum())
    fix = "; re-unwrap it into [0, 1], or remove the UVs and dpi derives an atlas"
    if outside:
        return f"{outside} of {len(uv)} mesh UVs lie outside [0, 1] (a tiled atlas): dpi's textures cover the unit square" + fix
    corners = uv[faces]
    edges = corners[:, 1:] - corners[:, :1]
    uv_area = 0.5 * np.abs(edges[:, 0, 0] * edges[:, 1, 1] - edges[:, 0, 1] * edges[:, 1, 0])
    if uv_area.sum() <= 1e-12:
        return "the mesh UVs have no area (all at one point or on a line): no texel would tell one face from another" + fix
    surface = max(float(areas.sum()), 1e-30)
    unmapped = float(areas[uv_area <= 1e-12 * uv_area.sum()].sum()) / surface
    if unmapped > UNMAPPED_SHARE:
        return f"{unmapped:.0%} of the surface's area lies on faces without area in the UV atlas: they get no texel" + fix
    return None


def true_surface(root: Path) -> dict[str, Path]:
    """{"mesh": gt/mesh.ply} when the capture holds the true surface, checked as the given mesh is (inside the
    capture, loads with faces and finite values) and to carry the UVs its textures are painted on; {} without one."""
    found = named_files(root / "gt", (TRUE_SURFACE,))[:1]
    if not found:
        return {}
    inside_capture(root, found[0], "the true surface (gt/mesh.ply)")
    check_mesh(found[0])
    if not mesh_has_uv(found[0]):
        raise CaptureError(f"{found[0]}: the true surface has no UVs (u, v vertex properties): gt/'s textures are "
                           "read through them")
    return {"mesh": found[0]}
