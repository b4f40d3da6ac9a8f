"""The capture's true materials on the problem's atlas: the evaluation's one reader of gt/ textures.

A capture whose UVs are given holds its true textures on that atlas. Where the atlas is derived (a given mesh without
UVs, as a scanner writes it, simplified and unwrapped by the uv stage), the true textures belong to gt/mesh.ply, the
true surface with its own UVs: each texel of the problem's atlas takes the truth's bilinear lookup at the nearest
point of that surface (open3d's closest-point query), as a texture-transfer bake does. Where the cameras are derived
the problem's surface is not in the truth's frame, and there is no truth to compare with.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
import torch

from dpi.capture import read_ground_truth
from dpi.capture.consistency import raycasting_scene
from dpi.capture.meshes import TRUE_SURFACE
from dpi.evaluation.metrics import missing
from dpi.evaluation.seams import texture_lookup
from dpi.io.images import resize
from dpi.io.layout import TEXTURE_NAMES
from dpi.preprocess.uv import bake
from dpi.render.renderer import mesh_arrays
from dpi.solve.decomposition import Decomposition
from dpi.solve.materials import MaterialTextures, resize_texture
from dpi.solve.problem import InverseProblem
from dpi.synth.shapes import TriangleMesh

def surface_lookup(surface: dict[str, np.ndarray], textures: list[np.ndarray], points: np.ndarray) -> np.ndarray:
    """(N, C) the textures' bilinear lookups (channels concatenated) at the points of `surface` (mesh_arrays)
    nearest to `points` (N, 3)."""
    import open3d as o3d

    scene = raycasting_scene(surface["positions"], surface["faces"])
    nearest = scene.compute_closest_points(o3d.core.Tensor(points.astype(np.float32)))
    triangle = nearest["primitive_ids"].numpy().astype(np.int64)
    b1, b2 = nearest["primitive_uvs"].numpy().astype(np.float64).T
    corners = surface["uvs"].astype(np.float64)[surface["faces"][triangle]]  # (N, 3, 2)
    uvs = (1 - b1 - b2)[:, None] * corners[:, 0] + b1[:, None] * corners[:, 1] + b2[:, None] * corners[:, 2]
    return np.concatenate([texture_lookup(t, uvs) for t in textures], axis=1)


@lru_cache(maxsize=8)
def transferred(surface_path: Path, target_path: Path, texture_paths: tuple[Path, ...], size: int
                ) -> tuple[np.ndarray, ...]:
    """The true textures (TEXTURE_NAMES order) carried from the true surface's atlas onto the target mesh's at
    size x size (module notes); read and baked once per process."""
    surface, target = mesh_arrays(surface_path), mesh_arrays(target_path)
    textures = [read_ground_truth(path, name) for path, name in zip(texture_paths, TEXTURE_NAMES)]
    mesh = TriangleMesh(target["positions"].astype(np.float64), target["faces"], target["uvs"].astype(np.float64))
    baked = bake(mesh, lambda points: surface_lookup(surface, textures, points), size)
    bounds = np.cumsum([t.shape[-1] for t in textures])[:-1]
    return tuple(np.ascontiguousarray(part) for part in np.split(baked, bounds, axis=-1))


def true_materials(problem: InverseProblem, size: int) -> MaterialTextures | str:
    """The capture's true textures on the problem's atlas at size x size (module notes), or the missing-value
    saying why there are none."""
    capture = problem.capture
    absent = [name for name in TEXTURE_NAMES if name not in capture.gt]
    if absent:
        return missing(f"no gt/{', gt/'.join(f'{n}.exr' for n in absent)}")
    paths = tuple(Path(capture.gt[name]) for name in TEXTURE_NAMES)
    if capture.provenance.get("uv") == "given":
        return MaterialTextures(*(resize_texture(torch.from_numpy(np.ascontiguousarray(read_ground_truth(p, n))), size)
                                  for p, n in zip(paths, TEXTURE_NAMES)))
    if capture.provenance.get("cameras") != "given":
        return missing("the cameras are derived: the recovered surface is not in the truth's frame")
    if "mesh" not in capture.gt:
        return missing(f"the atlas is derived and there is no gt/{TRUE_SURFACE} (the true surface with the UVs of "
                       "gt/'s textures)")
    return MaterialTextures(*(torch.from_numpy(t) for t in transferred(Path(capture.gt["mesh"]), Path(capture.mesh),
                                                                      paths, size)))


def true_decomposition(problem: InverseProblem) -> Decomposition | None:
    """The capture's true map and materials at the problem's sizes, in its normalised units, or None where gt/ lacks
    the map or the materials cannot be read on the problem's atlas."""
    materials = true_materials(problem, problem.settings.texture_size)
    if "envmap" not in problem.capture.gt or isinstance(materials, str):
        return None
    h = problem.settings.env_height
    env = resize(torch.from_numpy(np.ascontiguousarray(read_ground_truth(problem.capture.gt["envmap"], "envmap"))),
                 h, 2 * h)
    return problem.to_solver_units(Decomposition(env, materials))
