"""What an exported asset holds, read once for both formats: the mesh exactly as the renderer reads it, and per
sample its textures encoded as glTF and USD want them and its env map.

Texture convention: dpi's textures index rows by v (row 0 at v = 0, the UVs of the mesh as Mitsuba reads it),
which is glTF's convention; USD's `st` has t = 0 at the image's bottom row, so its writer flips v.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image

from dpi.io.exr import read_exr
from dpi.io.images import to_uint8
from dpi.io.layout import decomposition_files


@dataclass(frozen=True)
class AssetMesh:
    """A triangle mesh with one normal and one UV per vertex (float32), in dpi's frame (+Y up)."""

    positions: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray
    faces: np.ndarray


@dataclass(frozen=True)
class AssetSample:
    """One decomposition as a variant: its name (`dps 0`), file label (`dps_0`), folder and method."""

    method: str
    k: int | None
    folder: Path

    @property
    def name(self) -> str:
        return self.method if self.k is None else f"{self.method} {self.k}"

    @property
    def label(self) -> str:
        return self.name.replace(" ", "_")

    @property
    def files(self) -> dict[str, Path]:
        return decomposition_files(self.folder)


def renderer_mesh(path: str | Path) -> AssetMesh:
    """The mesh file as Mitsuba loads it for rendering (its UVs as the textures index them, smooth normals)."""
    from dpi.render.renderer import mesh_arrays

    mesh = mesh_arrays(path)
    if not mesh["uvs"].size:
        raise ValueError(f"{path}: the mesh has no UVs; a decomposition's textures need them")
    return AssetMesh(mesh["positions"], mesh["normals"], mesh["uvs"], mesh["faces"].astype(np.uint32))


def png_bytes(pixels: np.ndarray) -> bytes:
    """An 8-bit PNG of (H, W), (H, W, 1) or (H, W, 3) uint8 pixels."""
    out = io.BytesIO()
    Image.fromarray(pixels[..., 0] if pixels.ndim == 3 and pixels.shape[-1] == 1 else pixels).save(out, format="PNG")
    return out.getvalue()


def unit_to_uint8(values: np.ndarray) -> np.ndarray:
    """Linear values in [0, 1] as 8-bit (clipped, rounded)."""
    return np.round(np.clip(values, 0.0, 1.0) * 255).astype(np.uint8)


def chart_coverage(mesh: AssetMesh, size: int) -> np.ndarray:
    """(size, size) bool: the texels the mesh's charts read (dpi.render.texels.chart_texels)."""
    from dpi.render.texels import chart_texels

    return chart_texels(mesh.uvs.astype(np.float64), mesh.faces.astype(np.int64), size)


def sample_textures(sample: AssetSample, mesh: AssetMesh) -> dict[str, np.ndarray]:
    """A sample's textures as 8-bit images, their gutters filled from the mesh's charts (other renderers' lookups
    never read empty texels): `base_color` (sRGB), `metallic_roughness` (glTF's packing: roughness in green,
    metallic in blue, red unused at 255), and `roughness`, `metallic` alone (linear, for USD). A texture with a
    non-finite texel, not square or of another size than the others is refused, naming its file."""
    from dpi.render.texels import fill_gutters

    files = sample.files
    textures, coverage = {}, {}
    for name in ("albedo", "roughness", "metallic"):
        texture = read_exr(files[name])
        bad = ~np.isfinite(texture)
        if bad.any():
            raise ValueError(f"{files[name]}: {int(bad.any(-1).sum())} texels are NaN or infinite; the sample cannot "
                             "be exported (draw it again)")
        size = texture.shape[0]
        first = next(iter(textures.values()), texture).shape[:2]
        if texture.shape[1] != size or texture.shape[:2] != first:
            raise ValueError(f"{files[name]}: texture is {texture.shape[1]}x{size} px; a sample's textures are square "
                             f"and share one size (its first is {first[1]}x{first[0]}): draw the sample again")
        if size not in coverage:  # the three textures share one size: rasterise the charts once
            coverage[size] = chart_coverage(mesh, size)
        textures[name] = fill_gutters(texture, coverage[size])
    albedo, roughness, metallic = (textures[name] for name in ("albedo", "roughness", "metallic"))
    r8, m8 = unit_to_uint8(roughness[..., 0]), unit_to_uint8(metallic[..., 0])
    packed = np.stack([np.full_like(r8, 255), r8, m8], -1)
    return {"base_color": to_uint8(albedo[..., :3]), "metallic_roughness": packed, "roughness": r8, "metallic": m8}

