"""The sampled map's last data step: a nonnegative least-squares correction of its coarse light on the transport.

A sampler's steps correct the map near x0_hat in log radiance: a texel's change scales with its light, so a
window the prior left dark stays dark, and the sample keeps the prior's arrangement of the light where the
views ask for another. This step solves, on the recorded transport's grid (h rows) and in linear radiance,
  min_{x >= 0}  ||M x - y||^2 + ridge g (x - c)^T (I + smoothness Lap) (x - c)
with M the views' transport under the sample's albedo and roughness level, c the map area-resampled to h rows,
g the mean diagonal of M^T M (so `ridge` is unitless) and Lap the grid's Laplacian: light may appear where the
map had none, in smooth patches, and the map moves only as far as the views pull it. The correction x - c is
added to the map at its own size (Mitsuba's lookup of the coarse grid), so its finer detail stays the sample's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch

from dpi.images import resize
from dpi.solve.dps.map_solve import negative_laplacian
from dpi.solve.transport import LightTransport, lookup_upsample


@dataclass
class ProjectSettings:
    """The correction of the sampled map before the refinement (method_params.dps.project)."""

    enabled: bool = False
    """correct the map's coarse light by the views (transport samplers only: `proximal`, `gibbs`)"""
    ridge: float = 0.3
    """weight of the pull back to the sample, per unit of the views' mean squared transport"""
    smoothness: float = 4.0
    """weight of the correction's roughness (its Laplacian form) against its size"""
    iterations: int = 1000
    """accelerated projected-gradient iterations of the solve"""


def nonnegative_quadratic(matrix: torch.Tensor, rhs: torch.Tensor, start: torch.Tensor,
                          iterations: int) -> torch.Tensor:
    """argmin over x >= 0 of x^T A x / 2 - rhs^T x per channel: A (C, N, N) symmetric positive definite, rhs and
    start (C, N); accelerated projected gradient (FISTA) with the step 1 / the largest eigenvalue."""
    step = 1.0 / torch.linalg.eigvalsh(matrix)[:, -1:]
    x = start.clamp_min(0)
    y, t = x.clone(), 1.0
    for _ in range(iterations):
        gradient = (matrix @ y[:, :, None])[..., 0] - rhs
        x_next = (y - step * gradient).clamp_min(0)
        t_next = (1 + (1 + 4 * t * t) ** 0.5) / 2
        y = x_next + (t - 1) / t_next * (x_next - x)
        x, t = x_next, t_next
    return x


def project_map(env: torch.Tensor, transport: LightTransport, albedo: torch.Tensor, level: int,
                settings: ProjectSettings) -> tuple[torch.Tensor, dict[str, Any]]:
    """The map (H, 2H, 3) corrected by the views (module notes), and a record of the transport's relative fit
    before and after."""
    height = transport.height
    coarse = resize(env.detach().double(), height, 2 * height)
    current = coarse.reshape(-1, 3).T
    equations = transport.image_equations(albedo, level)
    gram, count = equations.gram, current.shape[1]
    scale = torch.diagonal(gram, dim1=1, dim2=2).mean(-1)[:, None, None]
    eye = torch.eye(count, dtype=gram.dtype)
    laplacian = negative_laplacian(eye.reshape(count, height, 2 * height)).reshape(count, count)
    penalty = settings.ridge * scale * (eye + settings.smoothness * laplacian)
    solution = nonnegative_quadratic(gram + penalty, equations.rhs + (penalty @ current[:, :, None])[..., 0],
                                     current, settings.iterations)
    change = (solution - current).T.reshape(height, 2 * height, 3)
    corrected = (env.double() + lookup_upsample(change, env.shape[0])).clamp_min(0).to(env.dtype)
    norm = float(transport.observed.double().square().sum())
    with torch.no_grad():
        before, after = (float(transport.fit_loss(m.float().reshape(-1, 3), albedo, level)) / norm
                         for m in (coarse, solution.T))
    return corrected, {"fit_before": before, "fit_after": after}
