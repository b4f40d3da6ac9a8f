"""Each sample's own reading of the light's broad balance: a broad albedo field over the object's normals.

A rough object's views fix albedo times irradiance, and irradiance varies with the normal as broadly as the light's
balance does: a brighter sky over a darker top renders the same shading as the truth. A sample that starts from a
uniform albedo gives every broad variation of the shading to the light, so all samples draw the same balance where
the views leave it open. Here, while the map settles and the materials are held (the proximal sampler's first
MATERIAL_START of the steps), each sample's albedo is the grey start times exp(G n): n the texel's smooth normal, G
(3 x 3, a direction per colour channel) drawn N(0, s^2) with s the init's albedo's own robust spread in log
luminance over the object's texels (how much this object's albedo is seen to vary). The map's solve draws the balance
that albedo implies; the field is then taken out, and the albedo, moving from then on, settles under that light.
"""

from __future__ import annotations

import numpy as np
import torch

from dpi.io.images import luminance
from dpi.render.texels import chart_of, texel_values, texture_from
from dpi.solve.problem import InverseProblem

MAD_TO_STD = 1.4826
"""a normal distribution's std over its median absolute deviation"""


def normal_texture(problem: InverseProblem, size: int) -> tuple[np.ndarray, np.ndarray]:
    """(size, size, 3) unit smooth normals of the problem's mesh in texture space, and its chart texels (size, size)."""
    mesh = problem.mesh
    covered, normals = texel_values(mesh["uvs"].astype(np.float64), mesh["faces"], mesh["normals"].astype(np.float64),
                                    size)
    normals = texture_from(covered, normals)
    normals /= np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-12)
    return normals, chart_of(covered)


def log_spread(albedo: np.ndarray, chart: np.ndarray) -> float:
    """Robust std (median absolute deviation) of an albedo's log luminance over the chart texels: how much the object's
    albedo varies, unmoved by the few texels a fit drives dark or bright."""
    values = np.log(np.maximum(luminance(albedo)[chart], 1e-4))
    if values.size < 2:
        return 0.0
    return float(MAD_TO_STD * np.median(np.abs(values - np.median(values))))


def balance_factor(normals: np.ndarray, spread: float, seed: int) -> torch.Tensor:
    """(size, size, 3) exp(G n), G (3 channels x 3 axes) drawn N(0, spread^2) from `seed`."""
    directions = np.random.default_rng(seed).normal(0.0, spread, (3, 3))
    return torch.from_numpy(np.exp(normals @ directions.T)).float()


def sample_balance_factor(problem: InverseProblem, init_albedo: torch.Tensor, dielectric: torch.Tensor,
                          seed: int) -> torch.Tensor:
    """A sample's broad albedo field (module notes) at the init's texture size, on the `dielectric` texels (size,
    size; bool) and 1 elsewhere: a metal's albedo is the colour of its reflections, which pin the light they show."""
    normals, chart = normal_texture(problem, init_albedo.shape[0])
    mask = dielectric.numpy()
    factor = balance_factor(normals, log_spread(init_albedo.detach().numpy(), chart & mask), seed)
    return torch.where(dielectric[..., None], factor, torch.ones_like(factor))
