"""Relighting and material editing (the paper's application): a decomposition re-rendered under
another environment map, from the capture's cameras or an orbit around the object, with edited
materials.

A decomposition is a folder as `Decomposition.save` writes it (envmap.exr, albedo.exr,
roughness.exr, metallic.exr): the init, or any method's sample. The new environment is any EXR,
turned about the up axis if asked and resampled to H x 2H. Every input is read and checked, and
every view rendered, before anything is written; then each view becomes a linear EXR and an sRGB
PNG, and relight.json records what was rendered.
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from dpi.capture import complete_capture, read_capture_json
from dpi.capture.cameras import Camera, from_fov, orbit
from dpi.io.atomic import write_json
from dpi.io.exr import write_exr
from dpi.io.images import resize, write_srgb
from dpi.io.layout import ENV_FILE, SceneLayout
from dpi.io.settings import Elevation, MapHeight, Rate, Steps, settings
from dpi.light.envmap import read_envmap, rotate_azimuth
from dpi.render.renderer import RenderConfig, Renderer
from dpi.solve.decomposition import Decomposition
from dpi.solve.materials import RANGES, MaterialTextures


@dataclass
class MaterialEdit:
    """Edits of a decomposition's textures before rendering (None: keep the texture)."""

    albedo_scale: tuple[float, float, float] | None = None
    """per-channel factor on the albedo (the result is clipped to [0, 1])"""
    roughness: float | None = None
    """constant roughness replacing the texture"""
    metallic: float | None = None
    """constant metallic replacing the texture"""

    def __post_init__(self) -> None:
        if self.albedo_scale is not None and (len(self.albedo_scale) != 3 or min(self.albedo_scale) < 0):
            raise ValueError(f"albedo_scale must be three non-negative factors, got {self.albedo_scale}")
        for name in ("roughness", "metallic"):
            value, (low, high) = getattr(self, name), RANGES[name]
            if value is not None and not low <= value <= high:
                raise ValueError(f"{name} must be in [{low}, {high}], got {value}")

    def apply(self, materials: MaterialTextures) -> MaterialTextures:
        """Edited copies of the textures, clamped to their valid ranges."""
        edited = materials.detached()
        if self.albedo_scale is not None:
            edited.albedo *= torch.tensor(self.albedo_scale, dtype=edited.albedo.dtype)
        if self.roughness is not None:
            edited.roughness.fill_(self.roughness)
        if self.metallic is not None:
            edited.metallic.fill_(self.metallic)
        return edited.clamp_()


@settings
class RelightConfig:
    """What to render: the environment, its rotation and resolution, the views, material edits."""

    envmap: str | None = None
    """EXR environment map to light with (None: the decomposition's own)"""
    rotate_deg: float = 0.0
    """turn the environment about the up axis (+Y), counter-clockwise seen from above"""
    env_height: MapHeight | None = None
    """height H the map is resampled to (None: the decomposition's map height)"""
    orbit: Steps = 0
    """render this many cameras on a ring around the object instead of the capture's cameras"""
    orbit_elevation_deg: Elevation = 20.0
    """elevation of the orbit cameras above the object's centre"""
    exposure: Rate = 1.0
    """factor applied before the PNGs' sRGB encoding (the EXRs stay linear)"""
    edit: MaterialEdit = field(default_factory=MaterialEdit)


def prepare_envmap(env: np.ndarray, height: int, rotate_deg: float = 0.0) -> np.ndarray:
    """The map turned by `rotate_deg` about the up axis (at its own resolution), then resampled to height x 2 height."""
    turned = np.ascontiguousarray(rotate_azimuth(env, rotate_deg), dtype=np.float32)
    return resize(torch.from_numpy(turned), height, 2 * height).numpy()


def orbit_cameras(reference: list[Camera], mesh: str | os.PathLike, count: int, elevation_deg: float) -> list[Camera]:
    """`count` cameras on a ring around the mesh's bounding-box centre, at the reference cameras'
    mean distance from it, with the first reference camera's image size and field of view."""
    import trimesh

    target = trimesh.load(mesh, force="mesh").bounds.mean(axis=0)
    radius = float(np.mean([np.linalg.norm(cam.center - target) for cam in reference]))
    first = reference[0]
    return [from_fov(pose, first.width, first.height, first.fov_x_deg, f"orbit_{i:03d}")
            for i, pose in enumerate(orbit(count, radius, (elevation_deg,), target))]


def relight(mesh: str | os.PathLike, cameras: list[Camera], env: np.ndarray, materials: MaterialTextures,
            render: RenderConfig, seed: int = 0) -> list[np.ndarray]:
    """Linear images (h, w, 3), one per camera, of the textured mesh under `env` (H, 2H, 3)."""
    renderer = Renderer(mesh, cameras, env.shape[0], materials.albedo.shape[0], render)
    env_t = torch.from_numpy(np.ascontiguousarray(env, dtype=np.float32))
    with torch.no_grad():
        return [renderer.render(env_t, materials.albedo, materials.roughness, materials.metallic, i, seed + i).numpy()
                for i in range(len(cameras))]


def write_views(out_dir: str | os.PathLike, names: list[str], images: list[np.ndarray], exposure: float) -> None:
    """{name}.exr (linear) and {name}.png (sRGB) per view, each written atomically."""
    for name, image in zip(names, images):
        write_exr(Path(out_dir) / f"{name}.exr", image)
        write_srgb(Path(out_dir) / f"{name}.png", image, exposure)


def relight_sample(capture_json: str | os.PathLike, sample_dir: str | os.PathLike, out_dir: str | os.PathLike,
                   cfg: RelightConfig, render: RenderConfig) -> list[str]:
    """Re-render the decomposition in `sample_dir` as `cfg` says into `out_dir`; returns the view names."""
    capture = complete_capture(read_capture_json(capture_json), SceneLayout(Path(capture_json).parent))
    if capture.mesh is None or not capture.mesh_has_uv:
        raise ValueError(f"{capture.root}: relighting needs the capture's mesh with UVs")
    decomposition = Decomposition.load(sample_dir)
    own = decomposition.env.numpy()
    source = read_envmap(cfg.envmap) if cfg.envmap else own
    env = prepare_envmap(source, cfg.env_height or own.shape[0], cfg.rotate_deg)
    materials = cfg.edit.apply(decomposition.materials)
    views = [(v.name, v.camera) for v in capture.views if v.camera is not None]
    if not views:
        raise ValueError(f"{capture_json}: the capture has no cameras to render from")
    if cfg.orbit:
        cameras = orbit_cameras([cam for _, cam in views], capture.mesh, cfg.orbit, cfg.orbit_elevation_deg)
        names = [cam.name for cam in cameras]
    else:
        names, cameras = [name for name, _ in views], [cam for _, cam in views]
    images = relight(capture.mesh, cameras, env, materials, render)
    write_views(out_dir, names, images, cfg.exposure)
    write_json(Path(out_dir) / "relight.json", {
        "sample": str(sample_dir), "envmap": cfg.envmap or str(Path(sample_dir) / ENV_FILE),
        "config": asdict(cfg), "env_shape": list(env.shape), "spp": render.spp, "views": names})
    return names
