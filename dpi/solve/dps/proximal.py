"""The proximal sampler (the DiffPIR / DDS family: Zhu et al. 2023, Chung et al. 2024): data steps on x0.

The data term acts on x0, not x_t, and needs no backward pass through the network. Each step
minimises, over the map's log radiance l (prior resolution), the exposure and the albedo,
  ||y - c R(exp(l + s), a)||^2 / ||y||^2  +  prox_weight abar_t / (1 - abar_t) ||z(l) - x0_hat||^2
with z(l) the map in prior space and R the training views' recorded light transport
(dpi.solve.dps.data_term): every step sees all the views, without path tracing. The views are linear
in the map, so the global exposure is solved exactly: c is the least-squares scale of the image, and
s += ln c. Each step first solves for l (`map_solve` Gauss-Newton iterations, dpi.solve.dps.map_solve,
materials and sun held): l is x0_hat's log radiance plus a correction on the transport's coarser grid,
so the views fix what they see at the resolution they see it and x0_hat keeps the finer detail (a few Adam
steps from x0_hat do not reach the views). The solve's target is x0_hat pushed by a smooth random field as
large as the prior's uncertainty about x0 at that step (`perturb`, as DAPS draws x0): where the views are
silent each sample keeps its own push, where they speak the solve pulls it back, so the samples' spread
follows what the views leave open. Then `inner_steps` Adam steps move map, albedo and sun together (on a
glossy init, dpi.solve.dps.start sets what changes). l starts from x0_hat at the first step and from the
previous step's l after that (DiffPIR's restart from each step's x0_hat lost the start's guess where the views
are silent).
Then re-noise:
x_{t-1} = sqrt(abar_{t-1}) z + sqrt(1 - abar_{t-1}) (sqrt(1 - zeta) eps_hat + sqrt(zeta) eps) with
eps_hat recomputed from z (zeta = NOISE_MIX), so samples stay diverse. The proximal weight grows as the noise falls
(DiffPIR's rho_t ~ 1 / sigma_t^2), so late steps keep what the data put into x_t early. Light and albedo move
together from the first step, the materials' Adam rates times abar_t, the signal's share of x_t: they move as firmly
as the map they are fitted under (an albedo held while the map settles hands the map its pattern; one free at its
full rate from a noisy x0_hat absorbs the map's errors). The roughness stays the init's: the transport is recorded
under it. It starts from the init map noised to `start_noise` (SDEdit). The refinement (dpi.solve.dps.refine) then
path-traces all the materials.

With a sun (dpi.solve.dps.sun_choice) the map is the prior's sky plus a parametric sun; its position and
irradiance are fitted with the rest, and a prior on its share of the map's energy settles what the
views cannot (a diffuse object barely tells a sun from a bright patch of sky around it).
"""

from __future__ import annotations

import math
from dataclasses import field
from typing import Any

import torch

from dpi.io.settings import Count, Rate, Share, Steps, Weight, settings, settings_from_dict
from dpi.solve.dps.data_term import sample_transport
from dpi.solve.dps.map_solve import PRIOR_STD, MapPrior, Resampling, cached_resampling, posterior_variance, solve_map
from dpi.solve.dps.state import DPSRun, DPSState, Laps, finite, log_radiance, predicted_step, recentre_
from dpi.solve.optimize import all_finite
from dpi.solve.sun_model import share_penalty, sun_env, wrap_uv_
from dpi.solve.transport import LightTransport, TransportConfig

MAX_EXPOSURE_STEP = 3.0
"""largest change of the log-exposure in one data update"""
GRAM_EVERY = 4
"""reverse steps one formed G of the views' normal equations serves the map's solve (the albedo moves little
between)"""
SOLVE_CG_ITERATIONS = 10
"""conjugate-gradient iterations of a step's solve on the transport's grid (more do not make it more accurate)"""


NOISE_MIX = 0.5
"""share zeta of fresh noise in the re-noising (0: deterministic DDIM, 1: all fresh)"""


@settings
class ProximalConfig:
    """The proximal x0-space sampler (method_params.dps.proximal)."""

    start_noise: Share = 0.4
    """noise level the reverse diffusion starts from, as a fraction of the schedule: the init map noised to that
    level (SDEdit), and that fraction of the steps run (1: from pure noise)"""
    transport: TransportConfig = field(default_factory=TransportConfig)
    """how the data term's light transport is recorded (dpi.solve.transport)"""
    inner_steps: Count = 1
    """joint data updates of map, materials and exposure per reverse step, after the map's solve"""
    lr_map: Rate = 0.05
    """Adam rate of the map's log radiance per data update"""
    prox_weight: Weight = 0.5
    """weight of ||z - x0_hat||^2 per unit abar_t / (1 - abar_t)"""
    map_solve: Steps = 1
    """Gauss-Newton iterations on the step's map (the same loss, all the views, dpi.solve.dps.map_solve) before
    its data updates: the map reaches the views from x0_hat, which a few Adam steps do not, by a correction of
    x0_hat on the transport's grid (finer detail stays x0_hat's; 0: Adam only)"""
    perturb: Weight = 0.35
    """the solve's target is x0_hat plus a smooth random field of perturb x the prior's std of x0 given x_t (r_t of
    DAPS, Zhang et al. 2024, for a prior of std PRIOR_STD): where the views are silent each sample's map moves as
    the prior allows instead of keeping x0_hat's guess, where they speak the solve pulls it back (0: samples near
    x0_hat's guess and alike; docs/studies.md, "the push's size" and "Light from real places")"""
    perturb_rows: Count = 2
    """rows of the grid the push is white on, upsampled onto the prior's (at most the transport's): 2, a field as
    broad as the light's balance between sky and ground, sides and colour; finer, the push reaches detail the
    views of a rough object do not see"""

    models_sun = True
    """sun mode auto gives this sampler's samples a parametric sun (dpi.solve.dps.sun_choice)"""

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> "ProximalConfig":
        """Settings from method_params.dps.proximal."""
        return settings_from_dict(cls, values)


def exposure_fit(transport: LightTransport, env: torch.Tensor, albedo: torch.Tensor) -> float:
    """The least-squares global scale c of the views' image under the map: they are linear in the map, so this
    is the exposure's exact optimum for the current map."""
    with torch.no_grad():
        image = transport.image(env, albedo).double()
        num, den = float((image * transport.observed).sum()), float(image.square().sum())
    c = num / den if den > 0 and math.isfinite(num / den) and num > 0 else 1.0
    return min(max(c, math.exp(-MAX_EXPOSURE_STEP)), math.exp(MAX_EXPOSURE_STEP))




def data_unit(run: DPSRun, transport: LightTransport) -> float:
    """The relative data term's divisor: residuals (pixels x channels) times the views' mean squared radiance."""
    return 3 * transport.pixels * run.data_norm


def relative_data_loss(run: DPSRun, transport: LightTransport, env: torch.Tensor,
                       albedo: torch.Tensor) -> torch.Tensor:
    """Mean squared residual per pixel and channel over the mean squared foreground radiance: ~1 / SNR
    (differentiable in the map and the albedo)."""
    return transport.fit_loss(env, albedo) / data_unit(run, transport)


def solve_step_map(run: DPSRun, state: DPSState, transport: LightTransport, x0_hat: torch.Tensor,
                   prox_weight: float, n: int, iterations: int) -> None:
    """Step n's map and exposure by Gauss-Newton `iterations` on the step's loss (its data and
    proximal terms; the materials and the sun held): its data sum / data_unit is sum / (2 sigma2), prox_weight x
    the mean is sum / (2 r^2). The views' normal equations are formed every GRAM_EVERY steps (the albedo moves
    little in between; the data updates after the solve see the current one). With `perturb` the target is pushed
    by a coarse random field (ProximalConfig.perturb)."""
    settings: ProximalConfig = run.sampler
    formed = int(state.normal_step)
    if formed < 0 or n - formed >= GRAM_EVERY:  # due: formed under the current albedo, which is kept for a resume
        with torch.no_grad():
            state.normal_albedo.copy_(state.materials.albedo)
        state.normal_step.fill_(n)
        state.extra.pop("gram", None)
    if "gram" not in state.extra:  # a resumed sample forms the ones in use again
        state.extra["gram"] = transport.image_equations(state.normal_albedo)
    equations = state.extra["gram"]
    sigma2 = data_unit(run, transport) / 2
    variance = x0_hat.numel() / (2 * max(prox_weight, 1e-12))
    extra = None
    if run.sun:
        per_exposure = run.sun_irradiance(state).detach() / torch.exp(state.log_exposure)
        extra = sun_env(state.sun_uv.detach(), per_exposure, transport.height).reshape(-1, 3).T
    basis = coarse_correction_(run, state, x0_hat, transport.height)
    prior = MapPrior(x0_hat, variance)
    if settings.perturb:  # x0_hat's coarse part shifted by a draw of the prior's uncertainty about x0 at this step
        abar = float(run.diffusion.alphas_cumprod[run.index(n)])
        height = min(settings.perturb_rows, transport.height)
        field = cached_resampling(state, height, run.prior.height)
        eta = torch.randn(3, field.forward.shape[1], generator=state.generator, dtype=torch.float64)
        std = settings.perturb * math.sqrt(posterior_variance(abar, PRIOR_STD))
        prior = MapPrior(x0_hat, variance, push=std * field.apply(eta))
    solve_map(run, state, equations, prior, sigma2, iterations, extra=extra, basis=basis,
              cg_iterations=SOLVE_CG_ITERATIONS)


def coarse_correction_(run: DPSRun, state: DPSState, x0_hat: torch.Tensor, height: int) -> Resampling:
    """Replace the map by x0_hat's log radiance plus the previous map's difference from it on the coarse grid of
    `height` rows (resampled there and back); returns that grid's upsampling onto the prior's (the solve's basis)."""
    down, up = cached_resampling(state, run.prior.height, height), cached_resampling(state, height, run.prior.height)
    with torch.no_grad():
        base = log_radiance(run, x0_hat)
        change = up.apply(down.apply((state.log_map - base).reshape(3, -1).double())).float()
        state.log_map.copy_(base + change.reshape(base.shape))
    return up


def proximal_step(run: DPSRun, state: DPSState, n: int) -> dict[str, Any]:
    """x0_hat, `inner_steps` joint data updates of (map, materials, exposure) near it, stochastic re-noising."""
    settings: ProximalConfig = run.sampler
    laps, i, gen = Laps(), run.index(n), state.generator
    encoding = run.prior.encoding
    record, x0_hat = predicted_step(run, state, n, laps)
    if x0_hat is None:
        return record
    abar = float(run.diffusion.alphas_cumprod[i])
    abar_prev = float(run.diffusion.alphas_cumprod_prev[i])
    prox_weight = settings.prox_weight * abar / (1.0 - abar)
    transport, recorded = sample_transport(run, state)
    laps.lap("transport")
    if n == 0:
        with torch.no_grad():
            state.log_map.copy_(log_radiance(run, x0_hat))
    if settings.map_solve:
        solve_step_map(run, state, transport, x0_hat, prox_weight, n, settings.map_solve)
    laps.lap("solve")
    losses, skipped = [], 0
    for _ in range(settings.inner_steps):
        env = run.env(torch.exp(state.log_map), state, transport.height)
        c = exposure_fit(transport, env, state.materials.albedo)
        state.log_exposure += math.log(c)
        data = relative_data_loss(run, transport, c * env, state.materials.albedo)
        prox = (encoding.to_prior(torch.exp(state.log_map)) - x0_hat).square().mean()
        loss = data + prox_weight * prox
        if run.sun:
            loss = loss + run.sun.prior_weight * share_penalty(run.sun_irradiance(state), env, run.sun.share)
        state.optimizer.zero_grad()
        if not finite(loss):
            skipped += 1
            continue
        loss.backward()
        if not all_finite([state.log_map, state.sun_uv, state.sun_log, *dict(state.materials.items()).values()]):
            skipped += 1
            continue
        for group in state.optimizer.param_groups:
            if group.get("material"):
                group["lr"] = group["base_lr"] * abar
        state.optimizer.step()
        run.problem.constrain_(state.materials)
        wrap_uv_(state.sun_uv)
        shift = recentre_(state.log_map, run.prior.median_target)
        state.log_exposure += shift
        with torch.no_grad():
            state.sun_log -= shift
        losses.append(float(data.detach()))
    laps.lap("data")
    with torch.no_grad():
        z = encoding.to_prior(torch.exp(state.log_map))
        eps_hat = (state.x - abar ** 0.5 * z) / (1.0 - abar) ** 0.5
        noise = torch.randn(z.shape, generator=gen)
        mixed = (1.0 - NOISE_MIX) ** 0.5 * eps_hat + NOISE_MIX ** 0.5 * noise
        state.x = abar_prev ** 0.5 * z + (1.0 - abar_prev) ** 0.5 * mixed
    return {**record, "loss": losses[-1] if losses else None, "prox": float(prox.detach()), "prox_weight": prox_weight,
            "log_exposure": float(state.log_exposure), "nan_inner": skipped, "refresh": recorded,
            **({"skipped": "non-finite loss or gradient"} if not losses else {}), **laps.record()}
