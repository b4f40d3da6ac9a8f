"""The atlas's seams, where one surface point has two UVs: which vertex copies and texels they join, and the tie that
keeps the textures' texels on both sides of a seam equal while they are solved.

An atlas cuts the surface into charts; a mesh edge on a cut appears in two faces with different UVs. Texels on
both sides of it belong to the same surface points, but a solve that fits each texel to the views alone lets them
drift apart, and every other renderer then shows the chart outlines. `SeamTies` samples each seam edge at half
a texel and joins the texel under each sample on one side with the texel under it on the other (union-find);
`tie_` replaces each joined group by its mean, the projection onto textures that agree across seams (it is called
with the materials' clamp after every update). Texel (row, col) covers v in [row/R, (row+1)/R) and u in
[col/R, (col+1)/R) of the mesh's UVs, as Mitsuba reads them (dpi.solve.transport.record.texture_weights).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

POSITION_DECIMALS = 6
"""vertex copies whose positions agree to this many decimals (of the mesh's extent) are one surface point"""


def position_groups(vertices: np.ndarray) -> np.ndarray:
    """(V,) one id per surface point: vertex copies at one position share it."""
    extent = max(float(np.ptp(vertices, axis=0).max()), 1e-12)
    keys = np.round((vertices - vertices.min(0)) / extent, POSITION_DECIMALS)
    return np.unique(keys, axis=0, return_inverse=True)[1].ravel()


def seam_pairs(vertices: np.ndarray, uvs: np.ndarray) -> np.ndarray:
    """(n, 2) vertex index pairs at one position with different UVs (the seams' two sides)."""
    group = position_groups(vertices)
    order = np.argsort(group, kind="stable")
    sorted_group = group[order]
    starts = np.flatnonzero(np.r_[True, sorted_group[1:] != sorted_group[:-1]])
    pairs = [(order[a], order[b]) for start, end in zip(starts, np.r_[starts[1:], len(order)])
             for a in range(start, end) for b in range(a + 1, end)]
    if not pairs:
        return np.zeros((0, 2), np.int64)
    pairs = np.asarray(pairs, np.int64)
    return pairs[np.abs(uvs[pairs[:, 0]] - uvs[pairs[:, 1]]).max(1) > 1e-9]


def mesh_edges(faces: np.ndarray) -> np.ndarray:
    """(n, 2) the mesh's unique edges (vertex index pairs)."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return np.unique(np.sort(edges, axis=1), axis=0)


def seam_edges(vertices: np.ndarray, faces: np.ndarray, uvs: np.ndarray) -> np.ndarray:
    """(n, 2, 2) pairs of vertex-index edges, one per side of a seam, their ends in the same order (the same
    surface points): mesh edges between two surface points that faces reach with different UVs."""
    group = position_groups(vertices)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    flip = group[edges[:, 0]] > group[edges[:, 1]]
    edges[flip] = edges[flip][:, ::-1]  # ends ordered by surface point
    keys = group[edges]
    order = np.lexsort((edges[:, 1], edges[:, 0], keys[:, 1], keys[:, 0]))
    edges, keys = edges[order], keys[order]
    same_place = (keys[1:] == keys[:-1]).all(1)
    other_uv = np.abs(uvs[edges[1:]] - uvs[edges[:-1]]).max(axis=(1, 2)) > 1e-9
    pick = np.flatnonzero(same_place & other_uv)
    return np.stack([edges[pick], edges[pick + 1]], 1)


def _find(parent: np.ndarray, i: np.ndarray) -> np.ndarray:
    """Roots of `i` in a union-find forest (path halving, vectorised)."""
    while True:
        up = parent[i]
        if (up == i).all():
            return i
        parent[i] = parent[up]
        i = parent[i]


@dataclass(frozen=True)
class SeamTies:
    """Groups of texels of an R x R texture that one surface point joins across seams: `texels` (n,) flat indices
    and `groups` (n,) their group ids (0 .. count - 1)."""

    size: int
    texels: torch.Tensor
    groups: torch.Tensor
    count: int

    @classmethod
    def of_mesh(cls, vertices: np.ndarray, faces: np.ndarray, uvs: np.ndarray, size: int) -> "SeamTies":
        """The ties of a mesh's seams in textures of `size` texels a side (module notes)."""
        sides = seam_edges(vertices, faces, uvs)
        if not len(sides):
            return cls(size, torch.zeros(0, dtype=torch.long), torch.zeros(0, dtype=torch.long), 0)
        ends = uvs[sides]  # (n, 2 sides, 2 ends, 2)
        length = np.abs(ends[:, :, 1] - ends[:, :, 0]).max(axis=(1, 2)) * size
        steps = np.maximum(np.ceil(2 * length).astype(np.int64), 1) + 1  # every half texel, ends included
        edge = np.repeat(np.arange(len(sides)), steps)
        s = (np.arange(steps.sum()) - np.repeat(np.cumsum(steps) - steps, steps)) / np.repeat(steps - 1, steps)
        points = ends[edge, :, 0] + s[:, None, None] * (ends[edge, :, 1] - ends[edge, :, 0])  # (m, 2 sides, 2)
        cells = np.clip(np.floor(points * size).astype(np.int64), 0, size - 1)
        flat = cells[..., 1] * size + cells[..., 0]  # (m, 2): row from v, column from u
        flat = flat[flat[:, 0] != flat[:, 1]]
        parent = np.arange(size * size)
        for a, b in flat:  # few thousand pairs: plain union-find
            ra, rb = _find(parent, np.array([a]))[0], _find(parent, np.array([b]))[0]
            if ra != rb:
                parent[max(ra, rb)] = min(ra, rb)
        texels = np.unique(flat)
        roots = _find(parent, texels)
        _, groups = np.unique(roots, return_inverse=True)
        return cls(size, torch.from_numpy(texels), torch.from_numpy(groups.ravel()), int(groups.max()) + 1)

    @torch.no_grad()
    def tie_(self, texture: torch.Tensor) -> torch.Tensor:
        """Replace each group's texels of an (R, R, C) texture by their mean, in place (the projection onto textures
        that agree across seams); returns the texture."""
        if not self.count:
            return texture
        flat = texture.view(-1, texture.shape[-1])
        values = flat[self.texels]
        sums = torch.zeros(self.count, values.shape[1], dtype=values.dtype).index_add_(0, self.groups, values)
        counts = torch.zeros(self.count, dtype=values.dtype).index_add_(0, self.groups, torch.ones_like(values[:, 0]))
        flat[self.texels] = (sums / counts[:, None])[self.groups]
        return texture
