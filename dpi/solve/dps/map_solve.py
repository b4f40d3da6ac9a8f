"""The map's log radiance given x0_hat and the views: Gauss-Newton with conjugate gradients on the transport.

The proximal sampler solves, at a reverse step, for the map's normalised log radiance l (prior resolution)
and the global log-exposure e:
  min  ||M (e^e (R s e^l + S)) - y||^2 / (2 sigma2) + ||z(l) - t||^2 / (2 r^2) - p^T (z(l) - t) / r^2
with M the views' transport under fixed materials (as normal equations), R the resampling from
the prior's grid to the transport's, s the radiance scale, S a fixed extra light (a parametric sun, per unit of
exposure), z the prior-space map, t its target (x0_hat) and p an optional push (the prior's mean moved by a
coarse random field, dpi.solve.dps.proximal). The exposure is solved exactly
before every Gauss-Newton iteration; each iteration's step is clamped to a trust region and halved until the
objective falls. With a `basis` the change of l lives on a coarser grid (`proximal`: the transport's); its
data steps then reach the views from x0_hat in one or two iterations, where a few Adam steps do not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import torch

from dpi.solve.dps.state import DPSRun, DPSState, finite, recentre_
from dpi.solve.prior_space import resample_env
from dpi.solve.transport import NormalEquations

RANGE_STD = 0.02
"""the prior's maps lie inside the encoding's range [-1, 1]: a solution beyond it pays (excess / RANGE_STD)^2 / 2"""
MAX_LOG_STEP = 3.0
"""largest change of a texel's log radiance in one Gauss-Newton iteration (a trust region)"""
CG_ITERATIONS = 20
PRIOR_STD = 0.5
"""std of a prior-space map's texel around its mean under the priors (their maps span [-1, 1]), for r_t"""
BACKTRACKS = 6


def conjugate_gradients(apply: Callable[[torch.Tensor], torch.Tensor], rhs: torch.Tensor, diagonal: torch.Tensor,
                        iterations: int, tolerance: float = 1e-6) -> torch.Tensor:
    """Solve apply(x) = rhs per row (a batch of symmetric positive definite systems) by conjugate gradients
    with a Jacobi preconditioner (`diagonal`), from x = 0."""
    x = torch.zeros_like(rhs)
    r = rhs.clone()
    z = r / diagonal
    d = z.clone()
    rz = (r * z).sum(-1, keepdim=True)
    goal = tolerance ** 2 * (rhs * rhs).sum(-1, keepdim=True)
    for _ in range(iterations):
        q = apply(d)
        step = rz / (d * q).sum(-1, keepdim=True).clamp_min(1e-300)
        x = x + step * d
        r = r - step * q
        if bool(((r * r).sum(-1, keepdim=True) <= goal).all()):
            break
        z = r / diagonal
        rz_next = (r * z).sum(-1, keepdim=True)
        d = z + rz_next / rz.clamp_min(1e-300) * d
        rz = rz_next
    return x


@dataclass(frozen=True)
class Resampling:
    """`resample_env` on one channel as sparse matrices (it is linear): A (N_env, N_prior), A^T, and (A o A)^T."""

    forward: torch.Tensor
    adjoint: torch.Tensor
    adjoint_squared: torch.Tensor

    @classmethod
    def between(cls, prior_height: int, env_height: int) -> "Resampling":
        """The matrices from the prior's resolution to the problem's, built by resampling unit maps."""
        units = torch.eye(2 * prior_height ** 2, dtype=torch.float64).reshape(-1, 1, prior_height, 2 * prior_height)
        columns = resample_env(units.reshape(-1, prior_height, 2 * prior_height)[None], env_height)
        a = columns.reshape(-1, units.shape[0])  # (N_env, N_prior): texel i of the map from prior texel j
        return cls(a.to_sparse(), a.T.contiguous().to_sparse(), a.square().T.contiguous().to_sparse())

    def apply(self, x: torch.Tensor) -> torch.Tensor:
        """(3, N_prior) -> (3, N_env)."""
        return (self.forward @ x.T).T

    def transpose(self, y: torch.Tensor) -> torch.Tensor:
        """(3, N_env) -> (3, N_prior)."""
        return (self.adjoint @ y.T).T


def cached_resampling(state: DPSState, from_height: int, to_height: int) -> Resampling:
    """`Resampling.between` the two grids, built once per sample (kept in state.extra)."""
    key = ("resampling", from_height, to_height)
    if key not in state.extra:
        state.extra[key] = Resampling.between(from_height, to_height)
    return state.extra[key]


def posterior_variance(abar: float, prior_std: float) -> float:
    """Var(x0 | x_t) per texel under a Gaussian prior of std `prior_std` at noise level abar."""
    s2 = prior_std ** 2
    return s2 * (1.0 - abar) / (1.0 - abar + abar * s2)


def prior_coordinates(encoding: Any, log_map: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The prior-space map z(l) of log radiance l (unclipped) and its elementwise slope dz/dl."""
    l = log_map.detach().requires_grad_(True)
    z = encoding.log_to_prior(l)
    (slope,) = torch.autograd.grad(z.sum(), l)
    return z.detach(), slope


@dataclass(frozen=True)
class MapPrior:
    """The map's prior around its target in prior space: variance r^2, optional push p (3, N)."""

    target: torch.Tensor
    variance: float
    push: torch.Tensor | None = None


def solve_map(run: DPSRun, state: DPSState, equations: NormalEquations, prior: MapPrior, sigma2: float,
              iterations: int, extra: torch.Tensor | None = None,
              basis: Resampling | None = None, cg_iterations: int = CG_ITERATIONS) -> float:
    """Gauss-Newton on the map's log radiance (state.log_map, from its current value, in place) and the
    log-exposure (module notes); `extra` (3, N) is S, `basis` (default: every texel) the coarser grid the change
    of l lives on, upsampled onto the prior's (l = l_start + B v: the finer detail stays the start's);
    `cg_iterations` bound each step's solve.
    The map is re-centred after (the shift moves into the exposure; the sun's log irradiance keeps its light).
    Returns the solution's prior term."""
    encoding = run.prior.encoding
    rhs = equations.rhs
    push = 0.0 if prior.push is None else prior.push
    target, variance = prior.target.reshape(3, -1).double(), prior.variance
    height = math.isqrt(equations.rhs.shape[1] // 2)  # the equations' map: H x 2H texels
    resampling = cached_resampling(state, run.prior.height, height)
    fixed = 0.0 if extra is None else extra.double()
    jacobi = (resampling.adjoint_squared @ equations.diagonal().T).T / sigma2  # diag of A^T G A, roughly
    start = state.log_map.detach().reshape(3, -1).double().clone()
    up = (lambda v: v) if basis is None else basis.apply
    down = (lambda g: g) if basis is None else basis.transpose
    down_squared = (lambda d: d) if basis is None else (lambda d: (basis.adjoint_squared @ d.T).T)
    v = torch.zeros(3, start.shape[1] if basis is None else basis.forward.shape[1], dtype=start.dtype)
    l = start
    log_exposure = float(state.log_exposure)

    def light(l: torch.Tensor) -> torch.Tensor:
        return resampling.apply(run.scale * torch.exp(l)) + fixed

    def objective(l: torch.Tensor, log_exposure: float) -> tuple[float, float]:
        """The negative log (data / 2 sigma^2 + prior + range) and its prior term."""
        sse = float(equations.sum_squares(math.exp(log_exposure) * light(l).T))
        z, _ = prior_coordinates(encoding, l)
        d = z - target
        value = (float(d.square().sum()) - 2 * float((push * d).sum())) / (2 * variance)
        beyond = float(((z.abs() - 1).clamp_min(0) / RANGE_STD).square().sum()) / 2
        return sse / (2 * sigma2) + value + beyond, value

    for _ in range(iterations):
        mapped = light(l)
        energy = equations.energy(mapped)
        projection = float((rhs * mapped).sum())
        if energy > 0 and projection > 0:
            log_exposure = math.log(projection / energy)
        u = math.exp(log_exposure) * run.scale * torch.exp(l)
        residual = (equations.apply(math.exp(log_exposure) * mapped) - rhs) / sigma2
        z, slope = prior_coordinates(encoding, l)
        outside = (z.abs() - 1).clamp_min(0) * z.sign()
        gradient = u * resampling.transpose(residual) + slope * ((z - target - push) / variance
                                                                 + outside / RANGE_STD ** 2)
        precision = slope.square() * (outside != 0) / RANGE_STD ** 2

        def hessian(x: torch.Tensor) -> torch.Tensor:
            x = up(x)
            return down(precision * x + slope * slope * x / variance
                        + u * resampling.transpose(equations.apply(resampling.apply(u * x)) / sigma2))

        diagonal = down_squared(precision + slope.square() / variance
                                + u.square() * jacobi)
        step = conjugate_gradients(hessian, -down(gradient), diagonal, cg_iterations)
        step = step.clamp(-MAX_LOG_STEP, MAX_LOG_STEP)
        current = objective(l, log_exposure)[0]
        for _ in range(BACKTRACKS):  # Gauss-Newton overshoots where exp bends: halve the step until it helps
            if objective(start + up(v + step), log_exposure)[0] < current:
                v = v + step
                l = start + up(v)
                break
            step = step / 2
    _, value = objective(l, log_exposure)
    if finite(l) and math.isfinite(log_exposure):
        with torch.no_grad():  # the sun's light is e^e S: its log irradiance stays, but for the re-centring
            state.log_map.copy_(l.reshape(state.log_map.shape).float())
            shift = recentre_(state.log_map, run.prior.median_target)
            state.log_exposure.fill_(log_exposure + shift)
            state.sun_log -= shift
    return value
