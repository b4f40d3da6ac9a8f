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

`bake` fills a texture with a function of the 3-D surface point each texel maps to, rasterising
all triangles at once in UV space (numpy, no loop over triangles), then spreads the charts'
edge texels into the gutters so bilinear lookups at seams never read empty texels.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from dpi.io.settings import Steps, settings
from dpi.synth.shapes import TriangleMesh


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
    edge collapse to one face per texel (normals, topology and open boundaries kept, so the silhouette stays)."""
    target = texture_size * texture_size
    if len(faces) <= FACES_PER_TEXEL * target:
        return vertices, faces
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.asarray(vertices, np.float64), face_matrix=np.asarray(faces, np.int32)))
    ms.meshing_decimation_quadric_edge_collapse(targetfacenum=target, preservenormal=True, preservetopology=True,
                                                preserveboundary=True, optimalplacement=True)
    mesh = ms.current_mesh()
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


def texel_centres_uv(size: int) -> tuple[np.ndarray, np.ndarray]:
    """(u, v) of every texel centre of a size x size texture, as (size, size) arrays (row 0 at v = 0)."""
    rows, cols = np.meshgrid(np.arange(size), np.arange(size), indexing="ij")
    return (cols + 0.5) / size, (rows + 0.5) / size


def rasterize_uv(mesh: TriangleMesh, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Triangle index (size, size) (-1: no triangle) and barycentric coordinates (size, size, 3) of
    each texel centre, all triangles at once."""
    tri_uv = mesh.uvs[mesh.faces]  # (F, 3, 2)
    col_f = tri_uv[..., 0] * size - 0.5
    row_f = tri_uv[..., 1] * size - 0.5
    c0 = np.clip(np.floor(col_f.min(1)).astype(np.int64), 0, size - 1)
    c1 = np.clip(np.ceil(col_f.max(1)).astype(np.int64), 0, size - 1)
    r0 = np.clip(np.floor(row_f.min(1)).astype(np.int64), 0, size - 1)
    r1 = np.clip(np.ceil(row_f.max(1)).astype(np.int64), 0, size - 1)
    ncols, nrows = c1 - c0 + 1, r1 - r0 + 1
    counts = ncols * nrows
    tri = np.repeat(np.arange(len(mesh.faces)), counts)
    offset = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    col = c0[tri] + offset % ncols[tri]
    row = r0[tri] + offset // ncols[tri]
    u, v = (col + 0.5) / size, (row + 0.5) / size
    a, b, c = tri_uv[tri, 0], tri_uv[tri, 1], tri_uv[tri, 2]
    e1, e2 = b - a, c - a
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    px, py = u - a[:, 0], v - a[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        w1 = (px * e2[:, 1] - py * e2[:, 0]) / det
        w2 = (e1[:, 0] * py - e1[:, 1] * px) / det
    w0 = 1.0 - w1 - w2
    eps = -1e-9
    inside = (np.abs(det) > 1e-20) & (w0 >= eps) & (w1 >= eps) & (w2 >= eps)
    index = np.full((size, size), -1, np.int64)
    bary = np.zeros((size, size, 3))
    index[row[inside], col[inside]] = tri[inside]
    bary[row[inside], col[inside]] = np.stack([w0, w1, w2], -1)[inside]
    return index, bary


def bake(mesh: TriangleMesh, function: Callable[[np.ndarray], np.ndarray], size: int) -> np.ndarray:
    """Texture (size, size, C) whose texels hold `function` (points (N, 3) -> values (N, C)) at the
    surface points they map to; gutter texels copy the nearest chart texel."""
    index, bary = rasterize_uv(mesh, size)
    covered = index >= 0
    points = np.einsum("nk,nkd->nd", bary[covered], mesh.vertices[mesh.faces[index[covered]]])
    values = np.asarray(function(points), dtype=np.float64)
    values = values.reshape(len(points), -1)
    texture = np.zeros((size, size, values.shape[1]))
    texture[covered] = values
    return fill_gutters(texture, covered).astype(np.float32)


def bake_vertex_values(mesh: TriangleMesh, values: np.ndarray, size: int) -> np.ndarray:
    """Texture (size, size, C) of per-vertex values (V, C) interpolated over the triangles each texel maps to (as
    `bake` places them; gutters copy the nearest chart texel): a mesh's smooth normals in texture space."""
    index, bary = rasterize_uv(mesh, size)
    covered = index >= 0
    texture = np.zeros((size, size, values.shape[1]))
    texture[covered] = np.einsum("nk,nkd->nd", bary[covered], values[mesh.faces[index[covered]]])
    return fill_gutters(texture, covered).astype(np.float32)


def chart_texels(mesh: TriangleMesh, size: int) -> np.ndarray:
    """(size, size) bool: the texels a bilinear lookup inside the charts reads (those whose centre a triangle covers,
    and their neighbours): what a solve fits; the rest is gutter."""
    from scipy.ndimage import binary_dilation

    return binary_dilation(rasterize_uv(mesh, size)[0] >= 0, np.ones((3, 3), bool))


def fill_gutters(texture: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """The texture with every texel outside `covered` copied from the nearest covered one, so other renderers'
    bilinear and mip-mapped lookups near chart borders never read empty texels."""
    from scipy.ndimage import distance_transform_edt

    if covered.all() or not covered.any():
        return texture
    _, (rows, cols) = distance_transform_edt(~covered, return_indices=True)
    return texture[rows, cols]


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
