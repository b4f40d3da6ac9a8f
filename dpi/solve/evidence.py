"""Which reading of the materials the training views favour: a Bayes factor from each reading's light transport.

A closing loss rewards a reading for explaining the views, not for needing few light parameters to: a metal under a
free map explains soft-lit views of a rough object a little better than the truth does, with a map that copies the
object's shading. The views are linear in the map through a reading's recorded light transport
(dpi.solve.transport), so each reading's marginal likelihood has a Laplace approximation at its fitted map, under a
Gaussian prior in log radiance whose mean and variance are the map's own. Per channel, with P residuals and N texels,
  log p(views) ~ -P/2 log(2 pi s_n^2) - P/2 - N/2 - 1/2 log det(I + s_l^2 J^T J / s_n^2)
where s_n^2 is the residual's mean square at the map (the views' noise and what the reading cannot explain), s_l^2
the variance of the map's log radiance, and J^T J = diag(u) G diag(u) the views' normal equations G in log radiance
at the map's radiance u. The log-determinant is the Occam factor: a reading whose transport lets the views pin more
directions of the map pays for each. A prior in log radiance leaves room for a sun, which one on linear radiance
does not (notebook/log.md, "the Bayes factor with a prior in log radiance").
"""

from __future__ import annotations

import math

import torch

from dpi.solve.transport import LightTransport, NormalEquations


def channel_log_evidence(gram: torch.Tensor, rhs: torch.Tensor, squares: float, count: int,
                         radiance: torch.Tensor) -> float:
    """One channel's log evidence (module notes) from its normal equations (G (N, N), b (N,), y^T y over `count`
    residuals) at the map's radiance (N,)."""
    u = radiance.double().clamp_min(1e-12)
    residual = float(u @ gram @ u - 2 * rhs @ u) + squares
    noise = max(residual / count, 1e-30)
    spread = float(torch.log(u).var())
    eigenvalues = torch.linalg.eigvalsh(u[:, None] * gram * u[None, :]).clamp_min(0)
    occam = float(torch.log1p(spread * eigenvalues / noise).sum())
    return -count / 2 * math.log(2 * math.pi * noise) - count / 2 - len(u) / 2 - occam / 2


def log_evidence(transport: LightTransport, env: torch.Tensor, albedo: torch.Tensor) -> float:
    """The views' log evidence under a reading (module notes): its transport, its fitted map (H, 2H, 3; area-resampled
    to the transport's grid and scaled by the least-squares exposure) and its albedo."""
    equations: NormalEquations = transport.image_equations(albedo)
    height = transport.height
    light = torch.nn.functional.interpolate(env.detach().permute(2, 0, 1)[None].double(), size=(height, 2 * height),
                                            mode="area")[0].reshape(3, -1)
    light = light * equations.exposure(light.T.reshape(height, 2 * height, 3))
    observed = transport.observed.double()
    return sum(channel_log_evidence(equations.gram[c], equations.rhs[c], float(observed[:, c].square().sum()),
                                    transport.pixels, light[c]) for c in range(3))


def glossy_probability(log_factor: float) -> float:
    """The glossy reading's posterior probability from the log Bayes factor glossy over rough (even prior odds)."""
    if log_factor >= 0:
        return 1.0 / (1.0 + math.exp(-log_factor))
    return math.exp(log_factor) / (1.0 + math.exp(log_factor))
