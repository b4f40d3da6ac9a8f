"""Differentiable rendering of one textured mesh under an environment map (Mitsuba 3, PyTorch-facing).

The measurement operator R(env, materials, camera) of the method: a Mitsuba scene with the mesh
(UV-mapped), a principled BSDF whose base colour, roughness and metallic are bitmap textures,
an `envmap` emitter, and one perspective sensor per view. The `prb` integrator (path replay
backpropagation) renders it; Dr.Jit's PyTorch interop (`dr.wrap`) makes `render` a torch
function whose gradients reach the environment map and the three textures.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import numpy as np
import torch
from pydantic import Field

from dpi.capture.cameras import Camera, pixel_rays, to_mitsuba
from dpi.io.settings import Count, SamplesPerPixel, settings
from dpi.light.envmap import pad_for_mitsuba
from dpi.render import backend

ENV_KEY = "emitter.data"
TEXTURE_KEYS = {
    "albedo": "object.bsdf.base_color.data",
    "roughness": "object.bsdf.roughness.data",
    "metallic": "object.bsdf.metallic.data",
}
SEED_MODULUS = 2**32 - 8192


@settings
class RenderConfig:
    """Path-tracing settings of the measurement operator."""

    spp: SamplesPerPixel = 16
    """samples per pixel of every differentiable render"""
    max_depth: Annotated[int, Field(ge=1, le=64)] = 5
    """Mitsuba path depth: 5 = direct light plus 4 bounces"""
    variant: Literal["auto", "llvm_ad_rgb", "cuda_ad_rgb"] = "auto"
    """Mitsuba variant: auto (cuda_ad_rgb with a GPU, else llvm_ad_rgb), or a name"""
    threads: Count | None = None
    """CPU threads for Dr.Jit and torch (None: leave as is)"""


def mesh_plugin(mesh_path: str | Path) -> dict:
    """Mitsuba shape dict for a .ply or .obj file."""
    suffix = Path(mesh_path).suffix.lower()
    if suffix not in (".ply", ".obj"):
        raise ValueError(f"{mesh_path}: unsupported mesh format (use .ply or .obj)")
    return {"type": suffix[1:], "filename": str(mesh_path), "face_normals": False}


def mesh_arrays(mesh_path: str | Path) -> dict[str, np.ndarray]:
    """The mesh as Mitsuba loads it for rendering: positions (V, 3), smooth normals (V, 3), UVs (V, 2; empty without
    them) as float32 and faces (F, 3) as int64, one UV per vertex as the textures index them."""
    from dpi.render import backend

    mi = backend.mitsuba()
    params = mi.traverse(mi.load_dict(mesh_plugin(mesh_path)))
    uvs = np.asarray(params["vertex_texcoords"], np.float32) if "vertex_texcoords" in params else np.zeros(0)
    return {"positions": np.asarray(params["vertex_positions"], np.float32).reshape(-1, 3),
            "normals": np.asarray(params["vertex_normals"], np.float32).reshape(-1, 3),
            "uvs": uvs.reshape(-1, 2), "faces": np.asarray(params["faces"], np.int64).reshape(-1, 3)}


def texture_plugin(data: np.ndarray) -> dict:
    """A linear (raw) bitmap texture of (size, size, channels) values, looked up bilinearly, clamped at the edges."""
    import mitsuba as mi

    return {"type": "bitmap", "bitmap": mi.Bitmap(np.ascontiguousarray(data, np.float32)), "raw": True,
            "filter_type": "bilinear", "wrap_mode": "clamp"}


class Renderer:
    """Renders views of one mesh for given env map and material textures, differentiably.

    env: (H, 2H, 3) linear radiance; albedo: (R, R, 3); roughness, metallic: (R, R, 1); all torch
    float32. `render` returns the (h, w, 3) linear image of one view.
    """

    def __init__(self, mesh_path: str | Path, cameras: list[Camera], env_height: int, texture_size: int,
                 settings: RenderConfig | None = None):
        self.settings = settings or RenderConfig()
        self.mi = backend.mitsuba(self.settings.variant, self.settings.threads)
        # dr.wrap picks the Dr.Jit backend from the tensors' device: cuda_ad_rgb needs them on the GPU
        self.device = torch.device("cuda") if self.mi.variant().startswith("cuda") else None
        import drjit as dr
        mi = self.mi
        self.cameras = list(cameras)
        self.env_height = env_height
        self.texture_size = texture_size
        scene = {
            "type": "scene",
            "integrator": {"type": "prb", "max_depth": self.settings.max_depth},
            "emitter": {"type": "envmap",
                        "bitmap": mi.Bitmap(np.ones((env_height, 2 * env_height, 3), np.float32))},
            "object": {**mesh_plugin(mesh_path), "bsdf": {
                "type": "principled",
                **{name: texture_plugin(np.full((texture_size, texture_size, channels), 0.5))
                   for name, channels in (("base_color", 3), ("roughness", 1), ("metallic", 1))},
            }},
        }
        for i, cam in enumerate(self.cameras):
            scene[f"sensor_{i:04d}"] = {
                **to_mitsuba(cam),
                "film": {"type": "hdrfilm", "width": cam.width, "height": cam.height,
                         "pixel_format": "rgb", "rfilter": {"type": "box"}},
                "sampler": {"type": "independent", "sample_count": self.settings.spp},
            }
        self.scene = mi.load_dict(scene)
        self.params = mi.traverse(self.scene)
        self.params.keep([ENV_KEY, *TEXTURE_KEYS.values()])
        self.env_data_width = self.params[ENV_KEY].shape[1]
        params, scene_ref = self.params, self.scene

        @dr.wrap(source="torch", target="drjit")
        def _render(env_data, albedo, roughness, metallic, view: int, seed: int, spp: int):
            params[ENV_KEY] = env_data
            params[TEXTURE_KEYS["albedo"]] = albedo
            params[TEXTURE_KEYS["roughness"]] = roughness
            params[TEXTURE_KEYS["metallic"]] = metallic
            params.update()
            return mi.render(scene_ref, params, sensor=view, spp=spp, seed=seed, seed_grad=seed + 7919)

        self._render = _render

    def render(self, env: torch.Tensor, albedo: torch.Tensor, roughness: torch.Tensor,
               metallic: torch.Tensor, view: int, seed: int = 0, spp: int | None = None) -> torch.Tensor:
        """Linear RGB image (h, w, 3) of `view`; differentiable in env and the textures."""
        self._check(env, (self.env_height, 2 * self.env_height, 3), "env")
        for name, tex, ch in (("albedo", albedo, 3), ("roughness", roughness, 1), ("metallic", metallic, 1)):
            self._check(tex, (self.texture_size, self.texture_size, ch), name)
        env_data = pad_for_mitsuba(env, self.env_data_width)
        seed = int(seed) % SEED_MODULUS  # Mitsuba seeds are 32-bit; seed_grad = seed + 7919 must fit too
        device = self.device or env.device
        image = self._render(*(t.to(device).contiguous() for t in (env_data, albedo, roughness, metallic)),
                             int(view), seed, int(spp or self.settings.spp))
        return image.to(env.device)

    def set_scene(self, env: torch.Tensor, albedo: torch.Tensor, roughness: torch.Tensor,
                  metallic: torch.Tensor) -> None:
        """Load a map and textures into the scene without rendering (for code that traces the scene itself,
        dpi.solve.transport); the map also becomes the emitter's importance-sampling distribution."""
        mi = self.mi
        self.params[ENV_KEY] = mi.TensorXf(np.ascontiguousarray(
            pad_for_mitsuba(env.detach().float(), self.env_data_width).cpu().numpy()))
        for name, tex in (("albedo", albedo), ("roughness", roughness), ("metallic", metallic)):
            self.params[TEXTURE_KEYS[name]] = mi.TensorXf(np.ascontiguousarray(tex.detach().float().cpu().numpy()))
        self.params.update()

    def object_hits(self, view: int, supersample: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Sub-pixel rays of `view` ((h, w, s*s, 3) origins and directions) and whether each hits the object."""
        mi = self.mi
        origins, dirs = pixel_rays(self.cameras[view], supersample)
        o, d = origins.reshape(-1, 3).astype(np.float32), dirs.reshape(-1, 3).astype(np.float32)
        ray = mi.Ray3f(mi.Point3f(o[:, 0], o[:, 1], o[:, 2]), mi.Vector3f(d[:, 0], d[:, 1], d[:, 2]))
        hits = np.array(self.scene.ray_test(ray), dtype=bool).reshape(origins.shape[:3])
        return origins, dirs, hits

    def coverage(self, view: int, supersample: int = 4) -> np.ndarray:
        """Fraction (h, w) of each pixel of `view` covered by the object (ray casting, s x s rays)."""
        return self.object_hits(view, supersample)[2].mean(-1)

    @staticmethod
    def _check(t: torch.Tensor, shape: tuple[int, ...], name: str) -> None:
        if tuple(t.shape) != shape:
            raise ValueError(f"{name}: expected shape {shape}, got {tuple(t.shape)}")
