"""A UV-mapped mesh's texture space: which triangle each texel centre lies in (all triangles rasterised at once,
numpy, no loop over triangles), per-vertex values interpolated there, the texels a lookup inside the charts reads,
and gutters filled from the nearest chart texel. Texel (row, col) of an R x R texture covers u in [col/R, (col+1)/R)
and v in [row/R, (row+1)/R) (dpi.preprocess.uv says why)."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import binary_dilation, distance_transform_edt


def rasterize_uv(uvs: np.ndarray, faces: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Triangle index (size, size) (-1: no triangle) and barycentric coordinates (size, size, 3) of each texel
    centre, for per-vertex `uvs` (V, 2) and `faces` (F, 3)."""
    tri_uv = uvs[faces]  # (F, 3, 2)
    col_f = tri_uv[..., 0] * size - 0.5
    row_f = tri_uv[..., 1] * size - 0.5
    c0 = np.clip(np.floor(col_f.min(1)).astype(np.int64), 0, size - 1)
    c1 = np.clip(np.ceil(col_f.max(1)).astype(np.int64), 0, size - 1)
    r0 = np.clip(np.floor(row_f.min(1)).astype(np.int64), 0, size - 1)
    r1 = np.clip(np.ceil(row_f.max(1)).astype(np.int64), 0, size - 1)
    ncols, nrows = c1 - c0 + 1, r1 - r0 + 1
    counts = ncols * nrows
    tri = np.repeat(np.arange(len(faces)), counts)
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


def texel_values(uvs: np.ndarray, faces: np.ndarray, values: np.ndarray, size: int
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The texels whose centre a triangle covers (size, size; bool) and per-vertex `values` (V, C) interpolated at
    those centres (n, C): a mesh's surface points or smooth normals in texture space."""
    index, bary = rasterize_uv(uvs, faces, size)
    covered = index >= 0
    return covered, np.einsum("nk,nkd->nd", bary[covered], values[faces[index[covered]]])


def texture_from(covered: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Texture (size, size, C) holding `values` (n, C) at the `covered` texels (size, size) and, in the gutters, the
    nearest covered texel's."""
    texture = np.zeros((*covered.shape, values.shape[1]))
    texture[covered] = values
    return fill_gutters(texture, covered).astype(np.float32)


def chart_of(covered: np.ndarray) -> np.ndarray:
    """(size, size) bool: the texels a bilinear lookup inside the charts reads, those a triangle covers (`covered`)
    and their neighbours: what a solve fits; the rest is gutter."""
    return binary_dilation(covered, np.ones((3, 3), bool))


def chart_texels(uvs: np.ndarray, faces: np.ndarray, size: int) -> np.ndarray:
    """`chart_of` the texels a mesh's triangles cover at `size`."""
    return chart_of(rasterize_uv(uvs, faces, size)[0] >= 0)


def fill_gutters(texture: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """The texture with every texel outside `covered` copied from the nearest covered one, so other renderers'
    bilinear and mip-mapped lookups near chart borders never read empty texels."""
    if covered.all() or not covered.any():
        return texture
    _, (rows, cols) = distance_transform_edt(~covered, return_indices=True)
    return texture[rows, cols]
