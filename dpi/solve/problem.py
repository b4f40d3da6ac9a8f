"""The inverse-rendering problem of one capture: observed views, masks, and the renderer R.

Everything a solver needs to evaluate the data term ||y_i - R(env, materials, c_i)||^2 over
masked foreground pixels, for any subset of training views. The images are held in normalised
units (divided by the capture's `exposure`, see dpi.solve.exposure), so every decomposition a solver
works on is too; decomposition files hold scene radiance, and `load_decomposition` /
`save_decomposition` convert at that boundary.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dpi.capture import Capture
from dpi.io.exr import EXRError
from dpi.io.images import read_image, read_mask, resize, working_size
from dpi.io.layout import SAMPLE_TRACE
from dpi.io.settings import ImageSize, MapHeight, TextureSize, settings, settings_from_dict
from dpi.render.renderer import RenderConfig, Renderer, mesh_arrays
from dpi.solve.decomposition import Decomposition
from dpi.solve.exposure import MIDDLE_GREY, capture_exposure
from dpi.solve.materials import MaterialTextures
from dpi.solve.seams import SeamTies



class CachedFileError(ValueError):
    """A file the workflow wrote earlier no longer reads; the message names it and how to rebuild it."""


@settings
class ProblemConfig:
    """Resolution of the unknowns and how the data term is measured."""

    env_height: MapHeight = 128
    """environment map height H (width 2H): finer than the prior's 32 rows, the prior's sample upsampled plus the
    detail the views fit"""
    texture_size: TextureSize | None = None
    """material texture resolution R (R x R texels), the one size the atlas is packed for and the textures are solved
    and exported at; None: follows the capture (`texture_size_for`)"""
    max_texture_size: TextureSize = 256
    """the largest R the capture's own size may ask for"""
    resolution: ImageSize | None = 96
    """longer image side (px) the views are fitted and evaluated at: larger captures are area-downsampled
    once (dpi.capture.working); None: the capture's own size"""


@dataclass
class SolveConfig:
    """Renderer and unknowns' resolution shared by init, methods and evaluation: the `render` and `problem`
    sections together (no key of its own; each section checks its fields)."""

    render: RenderConfig = field(default_factory=RenderConfig)
    problem: ProblemConfig = field(default_factory=ProblemConfig)

    @classmethod
    def from_config(cls, config: dict[str, Any], threads: int | None = None) -> "SolveConfig":
        """Settings from the `render` and `problem` sections of a workflow config, on `threads` threads."""
        render = settings_from_dict(RenderConfig, {**config.get("render", {}), "threads": threads})
        return cls(render, settings_from_dict(ProblemConfig, config.get("problem", {})))


MIN_TEXTURE_SIZE = 16
"""the smallest R a capture's own size gives"""


def texture_size_for(capture: Capture, settings: ProblemConfig, shares: list[float] | None = None) -> int:
    """R of the capture's textures: `settings.texture_size` when set, else about as many texels as the training views
    have object pixels at the working resolution (each view's mask share times its working pixel count), the power of
    two nearest in log, between MIN_TEXTURE_SIZE and `max_texture_size`. `shares`: the training views' mask shares
    when already read (default: read from the masks). The full-size capture and its working copy give the same R
    (mask shares, not pixel counts)."""
    if settings.texture_size:
        return settings.texture_size
    if shares is None:
        shares = [float(read_mask(v.mask).mean()) if v.mask else 1.0 for v in capture.views if not v.held_out]
    width, height = working_size(capture.image_size, settings.resolution)
    pixels = max(sum(shares) * width * height, 1.0)
    size = 2 ** round(np.log2(pixels) / 2)
    return int(min(max(size, MIN_TEXTURE_SIZE), settings.max_texture_size))


def to_loss_space(image: torch.Tensor) -> torch.Tensor:
    """Linear radiance (normalised: foreground median 0.18) as log(1 + x), the space the views are compared in: in
    linear HDR a mirror's glints of the sun outweigh the rest of its views and the fit places little else
    (docs/studies.md, "problem.loss_space")."""
    return torch.log1p(image.clamp_min(0))


class InverseProblem:
    """Observed images/masks of a capture's views and a differentiable renderer over all of them."""

    def __init__(self, capture: Capture, settings: ProblemConfig, render: RenderConfig):
        if capture.mesh is None or not capture.mesh_has_uv:
            raise ValueError(f"{capture.root}: inverse rendering needs a mesh with UVs")
        missing = [v.name for v in capture.views if v.camera is None]
        if missing:
            raise ValueError(f"{capture.root}: views without cameras: {', '.join(missing[:5])}")
        self.capture = capture
        self.views = list(capture.views)
        self.images = [torch.from_numpy(read_image(v.image)) for v in self.views]
        self.masks = [torch.from_numpy(read_mask(v.mask) if v.mask else np.ones(img.shape[:2], bool))
                      for v, img in zip(self.views, self.images)]
        shares = [float(m.float().mean()) for v, m in zip(self.views, self.masks) if not v.held_out]
        self.settings = settings = replace(settings, texture_size=texture_size_for(capture, settings, shares))
        self.renderer = Renderer(capture.mesh, [v.camera for v in self.views], settings.env_height,
                                 settings.texture_size, render)
        self.train_ids = [i for i, v in enumerate(self.views) if not v.held_out]
        self.held_out_ids = [i for i, v in enumerate(self.views) if v.held_out]
        if not self.train_ids:
            raise ValueError(f"{capture.root}: every view is held out; nothing to fit")
        self.exposure = capture_exposure([self.images[i] for i in self.train_ids],
                                         [self.masks[i] for i in self.train_ids], str(capture.root))
        """scene radiance per normalised unit: the images are divided by it"""
        self.images = [image / self.exposure for image in self.images]

    @cached_property
    def mesh(self) -> dict[str, np.ndarray]:
        """The mesh as the renderer reads it (dpi.render.renderer.mesh_arrays), read once."""
        return mesh_arrays(self.capture.mesh)

    @cached_property
    def seams(self) -> SeamTies:
        """The texels the mesh's seams join at the problem's texture size (dpi.solve.seams)."""
        mesh = self.mesh
        return SeamTies.of_mesh(mesh["positions"].astype(np.float64), mesh["faces"], mesh["uvs"].astype(np.float64),
                                self.settings.texture_size)

    def constrain_(self, materials: MaterialTextures) -> MaterialTextures:
        """Materials after an update, in place: clamped to their valid ranges and tied across the atlas's seams (the
        projection every solver applies after each step)."""
        materials.clamp_()
        for _, texture in materials.items():
            self.seams.tie_(texture.data)
        return materials

    def to_solver_units(self, decomposition: Decomposition) -> Decomposition:
        """A decomposition in scene radiance in the problem's normalised units."""
        return decomposition.scaled(1.0 / self.exposure)

    def to_scene_units(self, decomposition: Decomposition) -> Decomposition:
        """A decomposition in the problem's normalised units in scene radiance."""
        return decomposition.scaled(self.exposure)

    def load_decomposition(self, folder: str | Path) -> Decomposition:
        """A decomposition folder (scene radiance) in normalised units, its map and textures at the problem's
        size (an init of another size, e.g. one written before `env_height` changed, is resampled). A file of it
        that no longer reads (truncated or damaged on disk after it was written) is a CachedFileError saying how
        to rebuild it."""
        try:
            loaded = Decomposition.load(folder, self.settings.texture_size)
        except EXRError as exc:
            raise CachedFileError(f"{exc}; this cached result was damaged after it was written: delete the folder "
                                  f"{folder} and run the workflow again (it rebuilds what is missing, and what "
                                  "depends on it)") from None
        h = self.settings.env_height
        return self.to_solver_units(Decomposition(resize(loaded.env, h, 2 * h), loaded.materials, loaded.trace))

    def save_decomposition(self, decomposition: Decomposition, folder: str | Path,
                           trace_name: str = SAMPLE_TRACE) -> None:
        """Write a decomposition found in normalised units at scene radiance; its trace records the exposure."""
        if decomposition.trace is not None:
            decomposition.trace.info["exposure"] = {
                "scale": self.exposure,
                "definition": f"median positive foreground luminance of the training views / {MIDDLE_GREY}; "
                              "the solver saw the images divided by it (radiances in this trace are in those "
                              "units), the env map is written multiplied by it"}
        self.to_scene_units(decomposition).save(folder, trace_name)

    def render(self, env: torch.Tensor, materials: MaterialTextures, view: int, seed: int,
               spp: int | None = None) -> torch.Tensor:
        """Rendered linear image (h, w, 3) of view index `view`."""
        return self.renderer.render(env, materials.albedo, materials.roughness, materials.metallic,
                                    view, seed, spp)

    def view_loss(self, rendered: torch.Tensor, view: int) -> torch.Tensor:
        """Mean squared error over the foreground pixels of one view, in the loss space."""
        mask = self.masks[view][..., None].to(rendered.dtype)
        diff = to_loss_space(rendered) - to_loss_space(self.images[view])
        return (mask * diff.square()).sum() / (3 * mask.sum().clamp_min(1))

    def residual_norm(self, env: torch.Tensor, materials: MaterialTextures, views: list[int], seed: int) -> torch.Tensor:
        """||y - R(env, materials)|| over the foreground pixels of `views`: the DPS guidance loss,
        whose gradient keeps its size as the fit improves (unlike a mean of squares)."""
        total = torch.zeros(())
        for j, v in enumerate(views):
            rendered = self.render(env, materials, v, seed * 1009 + j)
            diff = to_loss_space(rendered) - to_loss_space(self.images[v])
            total = total + (self.masks[v][..., None].to(diff.dtype) * diff.square()).sum()
        return total.sqrt()

    def data_loss(self, env: torch.Tensor, materials: MaterialTextures, views: list[int], seed: int,
                  spp: int | None = None) -> torch.Tensor:
        """Sum of per-view foreground MSEs over `views` (each rendered with its own seed, at `spp` or the
        renderer's)."""
        return sum(self.view_loss(self.render(env, materials, v, seed * 1009 + j, spp), v)
                   for j, v in enumerate(views))

    def sample_views(self, count: int, generator: torch.Generator) -> list[int]:
        """`count` distinct training views drawn at random (all of them if count >= their number)."""
        if count >= len(self.train_ids):
            return list(self.train_ids)
        order = torch.randperm(len(self.train_ids), generator=generator)[:count]
        return [self.train_ids[i] for i in order.tolist()]
