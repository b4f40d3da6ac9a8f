"""UV atlas of a mesh (xatlas) and baking of functions of surface position into textures.

A mesh far denser than its textures can resolve is simplified first (`simplified_for_texture`), so that its charts
hold several texels each.

`parametrize` cuts the mesh into charts and packs them into the unit square; vertices on chart
seams are duplicated, so the result is a mesh with one UV per vertex, which Mitsuba reads from a
PLY (`write_uv_mesh` uses Mitsuba's own writer). Texel (row, col) of an R x R bitmap texture
covers u in [col/R, (col+1)/R) and v in [row/R, (row+1)/R) of the UVs *stored in the PLY*:
Mitsuba 3.9 reads PLY texture coordinates as they are and indexes bitmap rows by v (row 0 at
v = 0). Its OBJ loader flips v on reading (v -> 1 - v), so for an OBJ file the row is
R - 1 - floor(v R); dpi writes PLY. The round-trip test bakes, renders and compares.

`bake` fills a texture with a function of the 3-D surface point each texel maps to (the texture
space rasterised by dpi.render.texels), then spreads the charts' edge texels into the gutters so
bilinear lookups at seams never read empty texels.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from dpi.io.settings import Steps, settings
from dpi.render.texels import texel_values, texture_from
from dpi.synth.shapes import TriangleMesh

log = logging.getLogger(__name__)


@settings
class UVConfig:
    """Settings of the atlas."""

    padding: Steps = 2
    """texels between charts, at the size the textures are solved and exported at (ProblemConfig.texture_size)"""


FACES_PER_TEXEL = 2
"""most faces per texel of the texture a mesh is parametrised for: a denser mesh is simplified to one face per texel
first (quadric edge collapse), since its charts would be smaller than a texel"""


def simplified_for_texture(vertices: np.ndarray, faces: np.ndarray, texture_size: int
                           ) -> tuple[np.ndarray, np.ndarray]:
    """The mesh as it is, or, with more than FACES_PER_TEXEL faces per texel, simplified by pymeshlab's quadric
    edge collapse to one face per texel (normals, topology and open boundaries kept, so the silhouette stays). A
    scanner's mesh is first made one surface (coincident vertices merged, duplicate and zero-area faces removed,
    non-manifold edges and vertices repaired): a triangle soup or doubled faces are all boundary and collapse
    nowhere. Where the result is still denser than that, the log says so and why."""
    target = texture_size * texture_size
    if len(faces) <= FACES_PER_TEXEL * target:
        return vertices, faces
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.asarray(vertices, np.float64), face_matrix=np.asarray(faces, np.int32)))
    before = ms.get_topological_measures()
    ms.meshing_remove_duplicate_vertices()
    ms.meshing_remove_duplicate_faces()
    ms.meshing_remove_null_faces()
    ms.meshing_repair_non_manifold_edges()
    ms.meshing_repair_non_manifold_vertices()
    ms.meshing_remove_unreferenced_vertices()
    ms.meshing_decimation_quadric_edge_collapse(targetfacenum=target, preservenormal=True, preservetopology=True,
                                                preserveboundary=True, optimalplacement=True)
    mesh = ms.current_mesh()
    if mesh.face_number() > FACES_PER_TEXEL * target:
        log.warning("uv: the mesh keeps %d faces for %d x %d texels after simplification (given: %d faces, %d "
                    "non-manifold edges, %d boundary edges): its charts are smaller than a texel; a cleaner or "
                    "coarser mesh gives sharper textures", mesh.face_number(), texture_size, texture_size, len(faces),
                    before["non_two_manifold_edges"], before["boundary_edges"])
    return mesh.vertex_matrix(), mesh.face_matrix().astype(np.int64)


def parametrize(vertices: np.ndarray, faces: np.ndarray, texture_size: int,
                cfg: UVConfig | None = None) -> TriangleMesh:
    """Mesh with a UV atlas packed for texture_size x texture_size texels: vertices duplicated along chart seams,
    per-vertex UVs in [0, 1]."""
    import xatlas

    cfg = cfg or UVConfig()
    atlas = xatlas.Atlas()
    atlas.add_mesh(np.ascontiguousarray(vertices, np.float32), np.ascontiguousarray(faces, np.uint32))
    pack = xatlas.PackOptions()
    pack.resolution = texture_size
    pack.padding = cfg.padding
    atlas.generate(xatlas.ChartOptions(), pack)
    vmapping, indices, uvs = atlas[0]
    return TriangleMesh(np.asarray(vertices, np.float64)[vmapping], np.asarray(indices, np.int64),
                        np.asarray(uvs, np.float64))


def bake(mesh: TriangleMesh, function: Callable[[np.ndarray], np.ndarray], size: int) -> np.ndarray:
    """Texture (size, size, C) whose texels hold `function` (points (N, 3) -> values (N, C)) at the
    surface points they map to; gutter texels copy the nearest chart texel."""
    covered, points = texel_values(mesh.uvs, mesh.faces, mesh.vertices, size)
    return texture_from(covered, np.asarray(function(points), dtype=np.float64).reshape(len(points), -1))


def write_uv_mesh(path: str | Path, mesh: TriangleMesh) -> None:
    """Write a UV-mapped mesh as a PLY through Mitsuba's writer (Mitsuba reads it back exactly)."""
    from dpi.synth.shapes import write_ply

    write_ply(path, mesh)


def atlas_stage_summary(mesh: TriangleMesh, texture_size: int, seconds: float) -> dict:
    """Counts, texture size and time of an atlas, for the stage's summary."""
    return {"vertices": len(mesh.vertices), "faces": len(mesh.faces), "texture_size": texture_size,
            "seconds": round(seconds, 3)}


def uv_atlas(vertices: np.ndarray, faces: np.ndarray, texture_size: int,
             cfg: UVConfig | None = None) -> tuple[TriangleMesh, dict]:
    """`parametrize` (after `simplified_for_texture`) with a summary (vertex/face counts, the given mesh's faces,
    texture size, seconds)."""
    start = time.perf_counter()
    given = len(faces)
    vertices, faces = simplified_for_texture(vertices, faces, texture_size)
    mesh = parametrize(vertices, faces, texture_size, cfg)
    return mesh, {**atlas_stage_summary(mesh, texture_size, time.perf_counter() - start), "given_faces": given}
