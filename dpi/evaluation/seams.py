"""How visible a texture's chart seams are: the lookups on both sides of a seam against those along mesh edges.

An atlas cuts the surface into charts, so one surface point on a seam has two UVs (two vertex copies at one
position; dpi.solve.seams finds them and ties them while solving). A texture that is a function of the surface gives
both the same value; one solved texel by texel can disagree, and any renderer then shows the chart outlines.
`seam_ratio` is the mean absolute difference of the bilinear lookups (Mitsuba's,
dpi.solve.transport.record.texture_weights) at the two UVs of each seam vertex pair, over the mean difference
between the two ends of each mesh edge: about 1 or below for a seamless texture, far above where the charts disagree.
"""

from __future__ import annotations

import numpy as np

from dpi.solve.seams import mesh_edges, seam_pairs
from dpi.solve.transport.record import texture_weights


def texture_lookup(texture: np.ndarray, uvs: np.ndarray) -> np.ndarray:
    """(n, C) bilinear lookups of an (R, R, C) texture at uvs (n, 2), as the renderer reads it."""
    size = texture.shape[0]
    index, weight = texture_weights(uvs, size)
    flat = texture.reshape(size * size, -1).astype(np.float64)
    return (flat[index] * weight[..., None]).sum(1)


def seam_ratio(vertices: np.ndarray, faces: np.ndarray, uvs: np.ndarray, texture: np.ndarray) -> float:
    """Mean |lookup difference| across seam pairs over the same along mesh edges (module notes); NaN for a mesh
    without seams or a constant texture."""
    pairs = seam_pairs(vertices, uvs)
    if not len(pairs):
        return float("nan")
    values = texture_lookup(texture, uvs)
    across = np.abs(values[pairs[:, 0]] - values[pairs[:, 1]]).mean()
    edges = mesh_edges(faces)
    along = np.abs(values[edges[:, 0]] - values[edges[:, 1]]).mean()
    return float(across / along) if along > 0 else float("nan")
