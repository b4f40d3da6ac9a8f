"""The annealed sampler: decoupled annealing (DAPS, Zhang et al. 2024) on the recorded light transport.

Each reverse step draws a clean map z given x_t and all the views, then re-noises it with fresh noise:
x_{t-1} = sqrt(abar_{t-1}) z + sqrt(1 - abar_{t-1}) eps. The draw is randomise-then-optimise on
  ||y + sigma eta - c T L(z)||^2 / (2 sigma^2)  +  (z - x0_hat)^T Q (z - x0_hat) / (2 r_t^2)
- x0_hat by Tweedie from the randomly rolled network (as the other samplers); r_t^2 the variance of x0
  given x_t under a Gaussian prior of std `prior_std`: s^2 (1 - abar) / (1 - abar + abar s^2);
- Q = I + `smoothness` x the grid's Laplacian: the views correct x0_hat by a smooth field, not texel by
  texel (an i.i.d. Gaussian around x0_hat lets the views write T's noise into the map as speckle);
- T the training views' light transport (dpi.solve.transport): all views at every step, no render;
  c the global exposure (least squares); eta ~ N(0, I) in the views, drawn through T's normal
  equations as sigma G^(1/2) eta, so that for a linear model the minimiser is an exact posterior draw;
- sigma^2 the init's residual per pixel (rendered at NOISE_SPP) plus T's own noise under the current
  map (a draw must not fit the recording's noise).
Gauss-Newton with conjugate gradients minimises it over the map's log radiance (from the previous
draw, a few iterations, a backtracking line search). A point mass of data moves nothing where the
views are silent: there the draw stays at x0_hat and the samples differ as the prior's reverse process
makes them, from pure noise at `start_noise` on. The spread follows what the views leave open: a
mirror's views pin most texels, a rough object's only the broad light (and the albedo takes the rest).

The materials follow in a Gibbs alternation: from `material_start` of the steps on, every
`material_every` steps, `material_steps` Adam steps on them against path-traced renders of
`views_per_step` views under the current draw, and then T is recorded again under them (counted in
the trace). Every sample starts from a grey albedo (dpi.solve.init.starting_materials), as the other
samplers, so the albedo explores with the light. There is no parametric sun: a sun enters a sample only
where the views ask for one, through the data term.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import torch

from dpi.solve.dps.proximal import recentre_
from dpi.solve.dps.state import DPSRun, DPSState, Laps, SamplerSettings, finite, network_step
from dpi.solve.optimize import all_finite
from dpi.solve.prior_space import resample_env
from dpi.solve.transport import Transport, record_transport

NOISE_SPP = 64
"""samples per pixel of the init's renders that measure the views' noise (a 16 spp render doubles it)"""
DARK_FLOOR = 1e-6
"""radiance floor (times the prior's median) before the logarithm"""


@dataclass
class AnnealedSettings(SamplerSettings):
    """The annealed sampler (method_params.dps.annealed)."""

    views_per_step: int = 2
    """training views rendered per material step"""
    start_noise: float = 0.8
    """starts from pure noise at 0.8 of the schedule (x_t there is all but noise; above it the network's x0_hat
    saturates), so every sample explores the prior on its own"""
    noise_scale: float = 1.0
    """likelihood temperature: the per-pixel noise is the init's residual times this (larger: wider spread)"""
    prior_std: float = 0.5
    """std of a prior-space map around its mean, for r_t (the prior's own spread)"""
    smoothness: float = 4.0
    """the deviation of a draw from x0_hat is a smooth field: its prior precision is (I + smoothness x the grid's
    Laplacian) / r_t^2, so the views correct x0_hat over about sqrt(smoothness) texels, not texel by texel
    (an i.i.d. prior lets a noisy T write speckle into the map)"""
    solver_iterations: int = 3
    """Gauss-Newton iterations of each conditional draw (warm-started from the previous draw)"""
    material_start: float = 0.3
    """fraction of the steps before the materials move"""
    material_every: int = 8
    """reverse steps between two Gibbs phases of the materials (each followed by a new recording of T)"""
    material_steps: int = 8
    """Adam steps on the materials in a phase (each renders views_per_step views under the current draw)"""
    transport_spp: int = 32
    """paths per pixel of each recording of the light transport (light after the first bounce)"""
    transport_direct_spp: int = 4
    """camera samples per pixel of each recording's direct light (one shadow ray per texel each)"""


def posterior_variance(abar: float, prior_std: float) -> float:
    """Var(x0 | x_t) per texel under a Gaussian prior of std `prior_std` at noise level abar."""
    s2 = prior_std ** 2
    return s2 * (1.0 - abar) / (1.0 - abar + abar * s2)


def noise_variance(run: DPSRun, state: DPSState) -> float:
    """The per-pixel noise sigma^2 of the likelihood: the init's mean squared residual over the training views'
    foreground (one render each), times noise_scale^2 (stored on the state at the first step)."""
    if "noise" not in state.extra:
        problem, init = run.problem, run.init
        with torch.no_grad():
            total = sum(float((problem.masks[v][..., None] * (problem.render(init.env, init.materials, v, seed=7 + v,
                                                                             spp=NOISE_SPP)
                                                              - problem.images[v]).square()).sum())
                        for v in problem.train_ids)
        pixels = sum(int(problem.masks[v].sum()) * 3 for v in problem.train_ids)
        state.extra["noise"] = max(total / pixels, 1e-12 * run.data_norm) * run.sampler.noise_scale ** 2
    return state.extra["noise"]


def refresh_transport(run: DPSRun, state: DPSState, n: int, env: torch.Tensor) -> Transport:
    """Record the training views' light transport under the state's materials (guided by `env`), for the draws."""
    settings: AnnealedSettings = run.sampler
    transport = record_transport(run.problem, state.materials.detached(), env, settings.transport_spp,
                                 run.render_seed(n, 97), direct_spp=settings.transport_direct_spp)
    state.extra["transport"] = transport
    state.extra.pop("gram_factor", None)
    return transport


def material_phase(run: DPSRun, n: int) -> bool:
    """Whether step n opens with the materials' Gibbs steps: every material_every steps from material_start on."""
    settings: AnnealedSettings = run.sampler
    first = math.ceil(settings.material_start * run.num_steps)
    return n >= first and (n - first) % settings.material_every == 0


def gram_factor(state: DPSState, transport: Transport) -> torch.Tensor:
    """(3, N, N) a factor F with F F^T = G (+ a jitter of 1e-9 its mean diagonal), for the data perturbation."""
    if "gram_factor" not in state.extra:
        gram = transport.gram
        jitter = 1e-9 * gram.diagonal(dim1=1, dim2=2).mean(dim=1).clamp_min(1e-30)
        state.extra["gram_factor"] = torch.linalg.cholesky(gram + jitter[:, None, None] * torch.eye(gram.shape[-1],
                                                                                                     dtype=gram.dtype))
    return state.extra["gram_factor"]


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
        return cls(a.to_sparse_csr(), a.T.contiguous().to_sparse_csr(), a.square().T.contiguous().to_sparse_csr())

    def apply(self, x: torch.Tensor) -> torch.Tensor:
        """(3, N_prior) -> (3, N_env)."""
        return (self.forward @ x.T).T

    def transpose(self, y: torch.Tensor) -> torch.Tensor:
        """(3, N_env) -> (3, N_prior)."""
        return (self.adjoint @ y.T).T


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


def negative_laplacian(x: torch.Tensor) -> torch.Tensor:
    """(C, H, W) -> 4 x minus its four neighbours on the equirectangular grid (azimuth wraps; the poles' rows
    reflect): the graph Laplacian whose quadratic form sums the squared differences of neighbouring texels."""
    up = torch.cat([x[:, :1], x[:, :-1]], dim=1)
    down = torch.cat([x[:, 1:], x[:, -1:]], dim=1)
    return 4 * x - up - down - torch.roll(x, 1, dims=2) - torch.roll(x, -1, dims=2)


def prior_coordinates(encoding: Any, log_map: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The prior-space map z(l) of log radiance l (unclipped) and its elementwise slope dz/dl."""
    l = log_map.detach().requires_grad_(True)
    z = encoding.log_to_prior(l)
    (slope,) = torch.autograd.grad(z.sum(), l)
    return z.detach(), slope


RANGE_STD = 0.02
"""the prior's maps lie inside the encoding's range [-1, 1]: a draw beyond it pays (excess / RANGE_STD)^2 / 2"""
MAX_LOG_STEP = 3.0
"""largest change of a texel's log radiance in one Gauss-Newton iteration (a trust region)"""
CG_ITERATIONS = 30
BACKTRACKS = 6


def conditional_draw(run: DPSRun, state: DPSState, transport: Transport, x0_hat: torch.Tensor, variance: float,
                     sigma2: float) -> tuple[float, float]:
    """Randomise-then-optimise draw of the map's log radiance l (state.log_map, in place) and log-exposure
    (module notes): Gauss-Newton on l (conjugate gradients) with the exposure solved exactly before each
    iteration; returns the draw's data term (mean squared error per pixel and channel) and its prior term."""
    settings: AnnealedSettings = run.sampler
    gen, encoding = state.generator, run.prior.encoding
    shape = x0_hat.shape[-2:]

    def smooth(x: torch.Tensor) -> torch.Tensor:  # Q x = x + smoothness (minus the Laplacian) x, per channel
        return x + settings.smoothness * negative_laplacian(x.reshape(3, *shape)).reshape(3, -1)

    if "resampling" not in state.extra:
        state.extra["resampling"] = Resampling.between(run.prior.height, run.problem.settings.env_height)
    resampling: Resampling = state.extra["resampling"]
    target = x0_hat.reshape(3, -1).double()
    noise = torch.randn(transport.rhs.shape, generator=gen, dtype=transport.rhs.dtype)
    rhs = transport.rhs + math.sqrt(sigma2) * torch.einsum("cij,cj->ci", gram_factor(state, transport), noise)
    gram = transport.gram / sigma2
    jacobi = resampling.adjoint_squared @ gram.diagonal(dim1=1, dim2=2).T  # (N_prior, 3): diag of A^T H A
    l = state.log_map.detach().reshape(3, -1).double().clone()  # from the previous draw
    log_exposure = float(state.log_exposure)

    def objective(l: torch.Tensor, log_exposure: float) -> tuple[float, float, float]:
        """The perturbed posterior's negative log (data / 2 sigma^2 + prior + range), its data SSE, its prior."""
        env = math.exp(log_exposure) * resampling.apply(run.scale * torch.exp(l))
        sse = float(transport.sum_squares(env.T, rhs))
        z, _ = prior_coordinates(encoding, l)
        prior = float(((z - target) * smooth(z - target)).sum()) / (2 * variance)
        beyond = float(((z.abs() - 1).clamp_min(0) / RANGE_STD).square().sum()) / 2
        return sse / (2 * sigma2) + prior + beyond, sse, prior

    for _ in range(settings.solver_iterations):
        unit = run.scale * torch.exp(l)
        mapped = resampling.apply(unit)
        curvature = float((mapped * torch.einsum("cij,cj->ci", transport.gram, mapped)).sum())
        projection = float((rhs * mapped).sum())
        if curvature > 0 and projection > 0:
            log_exposure = math.log(projection / curvature)
        u = math.exp(log_exposure) * unit
        residual = torch.einsum("cij,cj->ci", gram, resampling.apply(u)) - rhs / sigma2
        z, slope = prior_coordinates(encoding, l)
        outside = (z.abs() - 1).clamp_min(0) * z.sign()
        gradient = u * resampling.transpose(residual) + slope * (smooth(z - target) / variance
                                                                 + outside / RANGE_STD ** 2)
        precision = slope.square() * (outside != 0) / RANGE_STD ** 2

        def hessian(x: torch.Tensor) -> torch.Tensor:
            return (precision * x + slope * smooth(slope * x) / variance
                    + u * resampling.transpose(torch.einsum("cij,cj->ci", gram, resampling.apply(u * x))))

        diagonal = precision + slope.square() * (1 + 4 * settings.smoothness) / variance + u.square() * jacobi.T
        step = conjugate_gradients(hessian, -gradient, diagonal, CG_ITERATIONS)
        step = step.clamp(-MAX_LOG_STEP, MAX_LOG_STEP)
        current = objective(l, log_exposure)[0]
        for _ in range(BACKTRACKS):  # Gauss-Newton overshoots where exp bends: halve the step until it helps
            if objective(l + step, log_exposure)[0] < current:
                l = l + step
                break
            step = step / 2
    _, sse, prior = objective(l, log_exposure)
    if finite(l) and math.isfinite(log_exposure):
        with torch.no_grad():
            state.log_map.copy_(l.reshape(x0_hat.shape).float())
            state.log_exposure.fill_(log_exposure + recentre_(state.log_map, run.prior.median_target))
    return sse / (3 * transport.pixels), prior


def material_step(run: DPSRun, state: DPSState, env: torch.Tensor, n: int, k: int) -> float | None:
    """One Adam step on the materials against renders of a few views under the (fixed) map; its loss."""
    views = run.views(state.generator)
    loss = run.problem.data_loss(env.detach(), state.materials, views, seed=run.render_seed(n, k))
    state.optimizer.zero_grad()
    if not finite(loss):
        return None
    loss.backward()
    if not all_finite([t for _, t in state.materials.items()]):
        return None
    state.optimizer.step()
    state.materials.clamp_()
    return float(loss.detach()) / len(views)


def annealed_step(run: DPSRun, state: DPSState, n: int) -> dict[str, Any]:
    """x0_hat, a conditional draw of the clean map given it and all the views, the materials' Gibbs steps, and
    the re-noising of the draw to the next level with fresh noise."""
    settings: AnnealedSettings = run.sampler
    laps, i, gen = Laps(), run.index(n), state.generator
    encoding = run.prior.encoding
    with torch.no_grad():
        p = network_step(run, state.x, i, gen)
    laps.lap("network")
    record: dict[str, Any] = {"step": n, "t": int(run.diffusion.timestep_map[i])}
    if not finite(p["x0"]):
        return {**record, "skipped": "non-finite network output", **laps.record()}  # keep x_t
    x0_hat = p["x0"]
    state.snapshots.append(x0_hat[0])
    if n == 0:
        with torch.no_grad():
            state.log_map.copy_(torch.log(encoding.to_radiance(x0_hat).clamp_min(DARK_FLOOR * run.prior.median_target)))
    losses: list[float | None] = []
    env = run.env(torch.exp(state.log_map), state).detach()
    if material_phase(run, n):  # Gibbs: the materials under the current map, then T under the new materials
        losses = [material_step(run, state, env, n, k) for k in range(settings.material_steps)]
    laps.lap("render")
    refreshed = "transport" not in state.extra or bool(losses)
    transport = refresh_transport(run, state, n, env) if refreshed else state.extra["transport"]
    laps.lap("transport")
    abar = float(run.diffusion.alphas_cumprod[i])
    abar_prev = float(run.diffusion.alphas_cumprod_prev[i])
    variance = posterior_variance(abar, settings.prior_std)
    sigma2 = noise_variance(run, state) + transport.noise(env)  # T's own noise too: a draw must not fit it
    data, prior = conditional_draw(run, state, transport, x0_hat, variance, sigma2)
    laps.lap("draw")
    with torch.no_grad():
        z = encoding.to_prior(torch.exp(state.log_map))
        state.x = abar_prev ** 0.5 * z + (1.0 - abar_prev) ** 0.5 * torch.randn(z.shape, generator=gen)
    skipped = sum(loss is None for loss in losses)
    return {**record, "loss": data, "prior": prior, "r2": variance, "refresh": refreshed,
            "material_loss": next((v for v in reversed(losses) if v is not None), None),
            "log_exposure": float(state.log_exposure), "nan_inner": skipped, **laps.record()}
