"""The lobe width a sample of a rough object starts from: the one its training views favour (`proximal.lobe_choice`).

The start's roughness is the init's, fitted under the init's uniform starting map, which leaves a rough lobe's width
unseen. With the choice, the sample's transport is recorded at LOBE_FACTORS more lobe widths of that texture (GGX
alpha = roughness^2 scaled texel by texel) in the same pass, and the sample keeps the level whose views a free
non-negative map explains best under the start's albedo: the map, the nuisance, at its best for each level, and the
residual measured by the product of the recording's two halves (unbiased by its noise). The start's uniform albedo,
not the init's, judges: the init's albedo was fitted around the init's lobe and favours it.
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.optimize import lsq_linear

from dpi.solve.transport import LightTransport, NormalEquations

LOBE_FACTORS = (0.5, 2 ** -0.5, 2 ** 0.5, 2.0)
"""lobe widths recorded beside the start's, over its: a factor 4 in alpha, a factor 2 in roughness, in even steps"""
RIDGE = 1e-9
"""relative weight on x^2 that keeps the normal equations positive definite where a texel is never seen"""


def nonnegative_quadratic(gram: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """argmin x^T G x - 2 b^T x over x >= 0 (G positive semi-definite): the non-negative least squares whose normal
    equations these are, solved on their Cholesky factor (a square problem of the unknowns' size)."""
    gram = gram + RIDGE * max(float(np.trace(gram)) / len(gram), 1e-30) * np.eye(len(gram))
    upper = np.linalg.cholesky(gram).T
    return lsq_linear(upper, np.linalg.solve(upper.T, rhs), bounds=(0, np.inf), method="bvls").x


def free_map(equations: NormalEquations, height: int) -> torch.Tensor:
    """(H, 2H, 3) the non-negative map of least squared residual under `equations` (per channel)."""
    light = [nonnegative_quadratic(equations.gram[c].numpy(), equations.rhs[c].numpy()) for c in range(3)]
    return torch.from_numpy(np.stack(light, axis=1)).reshape(height, 2 * height, 3)


def unexplained(transport: LightTransport, albedo: torch.Tensor, level: int) -> float:
    """Share of the views' energy a free non-negative map leaves at roughness level `level` under `albedo`."""
    env = free_map(transport.image_equations(albedo, level), transport.height)
    energy = float(transport.observed.double().square().sum())
    return float(transport.sum_squares(env, albedo.detach(), level)) / max(energy, 1e-30)


def favoured_level(transport: LightTransport, albedo: torch.Tensor) -> tuple[int, list[float]]:
    """The recorded roughness level whose views a free map explains best under `albedo`, and each level's share."""
    shares = [unexplained(transport, albedo, level) for level in range(len(transport.roughness))]
    return int(np.argmin(shares)), shares
