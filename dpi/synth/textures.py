"""Procedural ground-truth material textures (albedo, roughness, metallic) in UV space.

Textures are (R, R, C) arrays laid out as Mitsuba's bitmap textures read them (row 0 at v = 1).
Albedo has structure at several scales (colour patches, stripes, smooth noise) so that its
recovery is measurable; roughness and metallic vary mildly around given base values.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter


@dataclass
class Materials:
    """Material textures: albedo (R, R, 3) in [0, 1], roughness and metallic (R, R, 1)."""

    albedo: np.ndarray
    roughness: np.ndarray
    metallic: np.ndarray


def smooth_noise(size: int, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """Gaussian-filtered white noise in [0, 1], wrapping horizontally (u is periodic)."""
    field = gaussian_filter(rng.standard_normal((size, size)), sigma, mode=("nearest", "wrap"))
    field -= field.min()
    return field / max(field.max(), 1e-12)


def procedural_materials(size: int, roughness: float = 0.3, metallic: float = 0.0,
                         roughness_variation: float = 0.1, seed: int = 0) -> Materials:
    """Albedo with colour patches and stripes; roughness/metallic near their base values."""
    rng = np.random.default_rng(seed)
    palette = rng.uniform(0.1, 0.85, size=(4, 3))
    patches = smooth_noise(size, size / 10, rng)
    index = np.clip((patches * 4).astype(int), 0, 3)
    albedo = palette[index]
    v, u = np.meshgrid(np.linspace(0, 1, size), np.linspace(0, 1, size), indexing="ij")
    stripes = 0.5 + 0.5 * np.sign(np.sin(2 * np.pi * (6 * u + 2 * v)))
    albedo = albedo * (0.75 + 0.25 * stripes[..., None])
    albedo = albedo * (0.85 + 0.3 * smooth_noise(size, size / 32, rng)[..., None])
    rough = roughness + roughness_variation * (smooth_noise(size, size / 8, rng) - 0.5) * 2
    metal = np.full((size, size), float(metallic))
    return Materials(
        albedo=np.clip(albedo, 0.02, 0.95).astype(np.float32),
        roughness=np.clip(rough, 0.02, 1.0)[..., None].astype(np.float32),
        metallic=np.clip(metal, 0.0, 1.0)[..., None].astype(np.float32),
    )
