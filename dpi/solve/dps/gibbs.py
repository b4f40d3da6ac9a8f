"""The gibbs sampler: the map, the albedo and the views' noise drawn in turn on the recorded light transport.

The views are affine in the albedo and linear in the map under fixed roughness and metallic
(dpi.solve.transport), so with the transport recorded once per sample (under the starting
materials) a reverse step needs no path tracing. Each step, at noise level abar_t:
1. x0_hat by Tweedie from the randomly rolled network;
2. from `material_start` of the steps on, every `material_every` steps, a draw of the albedo given the
   map: the views are Gaussian in it, its prior is a smooth field around grey (std `albedo_std`,
   precision (I + `albedo_smoothness` x the texture grid's Laplacian) / albedo_std^2), and the draw is
   randomise-then-optimise (data and prior perturbed, conjugate gradients), clamped to [0, 1];
3. the views' noise: the mean squared residual of the current map and albedo over the recorded pixels,
   times noise_scale^2. The transport, the fixed roughness and a map of 2 H^2 texels do not explain the
   views exactly; a sampler that took only the cameras' noise as noise would be sure of a wrong answer;
4. a draw of the clean map z given x0_hat and all the views, as decoupled annealing (DAPS, Zhang et al.
   2024) draws it: its prior N(x0_hat, r_t^2 Q^-1), with r_t^2 the variance of x0 given x_t under a
   Gaussian prior of std `prior_std` and Q = I + `smoothness` x the map's Laplacian (the views correct
   x0_hat by a smooth field), times the views' likelihood through the transport with a global exposure
   solved exactly; randomise-then-optimise (prior mean and data perturbed) by Gauss-Newton with
   conjugate gradients on the map's log radiance, warm-started from the previous draw;
5. the re-noising x_{t-1} = sqrt(abar_{t-1}) z + sqrt(1 - abar_{t-1}) eps with fresh noise.
Where the views are silent the draw keeps its prior spread, so samples differ there as the prior's
maps do; where they speak, they agree. The sample starts from pure noise at `start_noise` of the
schedule. There is no parametric sun: a sun enters a sample only where the views ask for one. The
refinement (dpi.solve.dps.refine) then path-traces the materials under the drawn map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import torch

from dpi.solve.dps.map_solve import (PRIOR_STD, MapPrior, conjugate_gradients, negative_laplacian, posterior_variance,
                                     solve_map)
from dpi.solve.dps.state import DPSRun, DPSState, Laps, SamplerSettings, finite, log_radiance, predict_x0
from dpi.solve.dps.data_term import TransportSampling, current_level, sample_transport, set_level
from dpi.solve.init import START_ALBEDO
from dpi.solve.transport import LightTransport, NormalEquations

NOISE_FLOOR = 1e-6
"""lowest noise variance, times the views' mean squared radiance (a map and albedo that fit exactly)"""


@dataclass
class GibbsSettings(TransportSampling, SamplerSettings):
    """The gibbs sampler (method_params.dps.gibbs)."""

    start_noise: float = 0.8
    """starts from pure noise at 0.8 of the schedule (x_t there is all but noise; above it the network's x0_hat
    saturates), so every sample explores the prior on its own"""
    noise_scale: float = 1.0
    """likelihood temperature: the views' noise is the current residual times this (larger: wider spread)"""
    prior_std: float = PRIOR_STD
    """std of a prior-space map around its mean, for r_t (the prior's own spread)"""
    smoothness: float = 4.0
    """the map's deviation from x0_hat is a smooth field: its prior precision is (I + smoothness x the grid's
    Laplacian) / r_t^2, so the views correct x0_hat over about sqrt(smoothness) texels, not texel by texel"""
    solver_iterations: int = 2
    """Gauss-Newton iterations of each draw of the map (warm-started from the previous draw)"""
    material_start: float = 0.0
    """fraction of the steps before the roughness and the albedo are drawn"""
    material_every: int = 4
    """reverse steps between two draws of the albedo (each rebuilds the map's normal equations)"""
    albedo_anneal: float = 1.0
    """the albedo's draws weigh the views by abar_t to this power (0: fully from the first draw on): early draws
    follow the albedo's prior, so each sample settles the light/albedo trade-off from its own start"""
    albedo_std: float = 0.25
    """prior std of the albedo texture's mean level around grey (per channel)"""
    albedo_smoothness: float = 4.0
    """neighbouring albedo texels differ by about albedo_std / sqrt(albedo_smoothness) under the prior (AlbedoPrior)"""


def smooth_noise(shape: tuple[int, int, int], smoothness: float, wrap: bool, generator: torch.Generator,
                 mass: float = 1.0) -> torch.Tensor:
    """A draw of N(0, mass I + smoothness x the grid's Laplacian) (C, H, W): sqrt(mass) eps_0 + sqrt(smoothness)
    D^T eps_1, with D the difference along each edge of the grid (`negative_laplacian`'s edges), eps white noise."""
    c, h, w = shape
    out = math.sqrt(mass) * torch.randn(shape, generator=generator, dtype=torch.float64)
    polar = torch.randn(c, h - 1, w, generator=generator, dtype=torch.float64) * math.sqrt(smoothness)
    out[:, 1:] += polar
    out[:, :-1] -= polar
    azimuth = torch.randn(c, h, w if wrap else w - 1, generator=generator, dtype=torch.float64) * math.sqrt(smoothness)
    if wrap:
        out += torch.roll(azimuth, 1, dims=2) - azimuth
    else:
        out[:, :, 1:] += azimuth
        out[:, :, :-1] -= azimuth
    return out


ALBEDO_CG_ITERATIONS = 40


def gram_factor(equations: NormalEquations) -> torch.Tensor:
    """(3, N, N) a factor F with F F^T = G (+ a jitter of 1e-9 its mean diagonal), for the data perturbation."""
    gram = equations.gram
    jitter = 1e-9 * gram.diagonal(dim1=1, dim2=2).mean(dim=1).clamp_min(1e-30)
    return torch.linalg.cholesky(gram + jitter[:, None, None] * torch.eye(gram.shape[-1], dtype=gram.dtype))


def map_draw(run: DPSRun, state: DPSState, equations: NormalEquations, x0_hat: torch.Tensor, variance: float,
             sigma2: float) -> float:
    """Randomise-then-optimise draw of the map's log radiance (state.log_map, in place, from the previous draw)
    and log-exposure (module notes, step 4): the prior's mean perturbed by a draw of N(0, r_t^2 Q^-1) (written
    as Q^-1 times its precision's square root x eps), the data by one of the views' noise, then `solve_map`;
    `sigma2` is the noise variance of one residual of `equations`. Returns the draw's prior term."""
    settings: GibbsSettings = run.sampler
    gen = state.generator
    if "gram_factor" not in state.extra:
        state.extra["gram_factor"] = gram_factor(equations)
    push = math.sqrt(variance) * smooth_noise((3, *x0_hat.shape[-2:]), settings.smoothness, True, gen).reshape(3, -1)
    noise = torch.randn(equations.rhs.shape, generator=gen, dtype=torch.float64)
    rhs = equations.rhs + math.sqrt(sigma2) * torch.bmm(state.extra["gram_factor"], noise[:, :, None])[..., 0]
    return solve_map(run, state, equations, MapPrior(x0_hat, variance, settings.smoothness, push), sigma2,
                     settings.solver_iterations, rhs)


def albedo_draw(settings: GibbsSettings, transport: LightTransport, env: torch.Tensor, albedo: torch.Tensor,
                level: int, sigma2: float, generator: torch.Generator) -> torch.Tensor:
    """Randomise-then-optimise draw of the (R, R, 3) albedo given the map (module notes, step 2): the views'
    quadratic in the albedo each pixel sees (`LightTransport.albedo_terms`, through the sparse lookup), weighted
    for the pixels not recorded, plus the prior, each perturbed by a draw of its own noise; conjugate gradients
    from the current albedo, then clamped to [0, 1]."""
    curvature, linear, _ = transport.albedo_terms(env, level)
    lookup, size = transport.lookup, albedo.shape[0]
    precision = transport.weight / sigma2
    observed = linear + (curvature * sigma2 / transport.weight).sqrt() * torch.randn(
        linear.shape, generator=generator, dtype=torch.float64)
    current = albedo.detach().double().reshape(-1, 3).T
    prior, push = albedo_prior(settings, size, generator)

    def hessian(x: torch.Tensor) -> torch.Tensor:
        return lookup.adjoint(lookup.apply(x.T) * curvature * precision).T + prior(x)

    mean = torch.full_like(current, START_ALBEDO)
    gradient = lookup.adjoint((lookup.apply(current.T) * curvature - observed) * precision).T \
        + prior(current - mean) - push
    diagonal = lookup.squared().adjoint(curvature * precision).T + prior.diagonal
    step = conjugate_gradients(hessian, -gradient, diagonal, ALBEDO_CG_ITERATIONS)
    return (current + step).T.reshape(size, size, 3).clamp(0, 1).float()


@dataclass(frozen=True)
class AlbedoPrior:
    """The albedo's Gaussian prior as its precision (I / R^2 + albedo_smoothness x the texture grid's Laplacian) /
    albedo_std^2 per channel: the texture's mean level has std albedo_std around grey, the light's colour and
    balance are free to trade with it, and neighbouring texels differ by about albedo_std / sqrt(smoothness)."""

    size: int
    std: float
    smoothness: float

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        """The precision times x (3, R^2)."""
        grid = negative_laplacian(x.reshape(3, self.size, self.size), wrap=False).reshape(3, -1)
        return (x / self.size ** 2 + self.smoothness * grid) / self.std ** 2

    @property
    def diagonal(self) -> float:
        """The precision's largest diagonal entry (for the preconditioner)."""
        return (1 / self.size ** 2 + 4 * self.smoothness) / self.std ** 2


def albedo_prior(settings: GibbsSettings, size: int, generator: torch.Generator) -> tuple[AlbedoPrior, torch.Tensor]:
    """The albedo's prior and a draw of N(0, its precision) (3, R^2), the perturbation of a randomise-then-optimise
    draw."""
    prior = AlbedoPrior(size, settings.albedo_std, settings.albedo_smoothness)
    noise = smooth_noise((3, size, size), settings.albedo_smoothness, False, generator, mass=1 / size ** 2)
    return prior, noise.reshape(3, -1) / settings.albedo_std


def residual_variance(transport: LightTransport, env: torch.Tensor, albedo: torch.Tensor, floor: float,
                      level: int) -> float:
    """The mean squared residual per recorded pixel and channel of a map, an albedo and a roughness level
    (unbiased: the halves' product), at least `floor`."""
    with torch.no_grad():
        return max(float(transport.sum_squares(env, albedo, level)) / (3 * transport.pixels), floor)


def level_draw(transport: LightTransport, env: torch.Tensor, albedo: torch.Tensor, sigma2: float,
               generator: torch.Generator) -> int:
    """A draw of the roughness level given the map and the albedo: each level's views likelihood (the residual
    over the recorded pixels, weighted for the rest, under noise variance sigma2), a uniform prior."""
    log_p = -transport.level_sum_squares(env, albedo) * transport.weight / (2 * sigma2)
    p = torch.softmax(log_p - log_p.max(), dim=0)
    return int(torch.multinomial(p.float(), 1, generator=generator))


def albedo_phase(run: DPSRun, n: int) -> bool:
    """Whether step n draws the albedo: every material_every steps from material_start on."""
    settings: GibbsSettings = run.sampler
    first = math.ceil(settings.material_start * run.num_steps)
    return n >= first and (n - first) % settings.material_every == 0


def gibbs_step(run: DPSRun, state: DPSState, n: int) -> dict[str, Any]:
    """x0_hat, (every few steps) a draw of the albedo, the views' noise, a draw of the map given x0_hat and all
    the views, and its re-noising to the next level with fresh noise (module notes)."""
    settings: GibbsSettings = run.sampler
    laps, i, gen = Laps(), run.index(n), state.generator
    encoding = run.prior.encoding
    record, x0_hat = predict_x0(run, state, n, laps)
    if x0_hat is None:
        return record
    if n == 0:
        with torch.no_grad():
            state.log_map.copy_(log_radiance(run, x0_hat))
    transport, recorded = sample_transport(run, state)
    env = run.env(torch.exp(state.log_map), state, transport.height).detach()
    level = current_level(transport, state.materials.roughness)
    laps.lap("transport")
    floor = NOISE_FLOOR * run.data_norm
    drew_albedo = albedo_phase(run, n)
    if drew_albedo:  # the roughness level, then the albedo, from the views tempered by abar_t (module notes)
        temper = float(run.diffusion.alphas_cumprod[i]) ** settings.albedo_anneal
        sigma2 = residual_variance(transport, env, state.materials.albedo, floor, level) * settings.noise_scale ** 2
        level = level_draw(transport, env, state.materials.albedo, sigma2 / temper, gen)
        albedo = albedo_draw(settings, transport, env, state.materials.albedo, level, sigma2 / temper, gen)
        set_level(state, transport, level)
        if finite(albedo):
            with torch.no_grad():
                state.materials.albedo.copy_(albedo)
        state.extra.pop("equations", None)
    laps.lap("albedo")
    if "equations" not in state.extra:
        state.extra["equations"] = transport.light_equations(state.materials.albedo, level)
        state.extra.pop("gram_factor", None)
    equations: NormalEquations = state.extra["equations"]
    laps.lap("equations")
    with torch.no_grad():  # the residual of the map and albedo so far (the normal equations give it at no cost)
        sigma2 = max(float(equations.sum_squares(env)) / equations.count, floor) * settings.noise_scale ** 2
    abar = float(run.diffusion.alphas_cumprod[i])
    abar_prev = float(run.diffusion.alphas_cumprod_prev[i])
    variance = posterior_variance(abar, settings.prior_std)
    prior = map_draw(run, state, equations, x0_hat, variance, sigma2 / transport.weight)
    laps.lap("draw")
    with torch.no_grad():
        z = encoding.to_prior(torch.exp(state.log_map))
        state.x = abar_prev ** 0.5 * z + (1.0 - abar_prev) ** 0.5 * torch.randn(z.shape, generator=gen)
    return {**record, "loss": sigma2 / settings.noise_scale ** 2, "prior": prior, "r2": variance,
            "refresh": recorded, "albedo": drew_albedo, "roughness_level": level, "log_exposure": float(state.log_exposure), **laps.record()}
