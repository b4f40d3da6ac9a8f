"""The proximal sampler (the DiffPIR / DDS family: Zhu et al. 2023, Chung et al. 2024): data steps on x0.

The data term acts on x0, not x_t, and needs no backward pass through the network.
`inner_steps` Adam steps on the map's log radiance l (prior resolution) and the materials against
  ||y - c R(exp(l + s), k)||^2 / ||y||^2  +  prox_weight abar_t / (1 - abar_t) ||z(l) - x0_hat||^2
with z(l) the map in prior space, over `views_per_step` views per inner step (one render and one
backward feed both). The renderer is linear in the map, so the global exposure is solved exactly:
c is the least-squares scale of each render, and s += ln c. l starts from x0_hat at the first step
and from the previous step's l after that (the data fit accumulates). Then re-noise:
x_{t-1} = sqrt(abar_{t-1}) z + sqrt(1 - abar_{t-1}) (sqrt(1 - zeta) eps_hat + sqrt(zeta) eps) with
eps_hat recomputed from z, so samples stay diverse. The proximal weight grows as the noise falls
(DiffPIR's rho_t ~ 1 / sigma_t^2), so late steps keep what the data put into x_t early. The
materials move only after `material_start` of the steps: while x0_hat is still a blur, free albedo
steps would absorb the map's errors. It starts from the init map noised to `start_noise` (SDEdit).

With a sun (dpi.solve.dps.sun) the map is the prior's sky plus a parametric sun; its position and
irradiance are fitted with the rest, and a prior on its share of the map's energy settles what the
views cannot (a diffuse object barely tells a sun from a bright patch of sky around it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import torch

from dpi.images import luminance
from dpi.solve.dps.state import DPSRun, DPSState, Laps, SamplerSettings, finite, network_step
from dpi.solve.optimize import all_finite
from dpi.solve.sun import share_penalty, wrap_uv_

MAX_EXPOSURE_STEP = 3.0
"""largest change of the log-exposure in one data update"""
DARK_FLOOR = 1e-6
"""radiance floor (times the prior's median) before the logarithm (the paper's curve reaches 0)"""


@dataclass
class ProximalSettings(SamplerSettings):
    """The proximal x0-space sampler (method_params.dps.proximal)."""

    views_per_step: int = 4
    """training views rendered per data update"""
    spp: int | None = None
    """samples per pixel of the data term's renders (None: the renderer's)"""
    start_noise: float = 0.4
    """starts from the init map noised to 0.4 of the schedule (SDEdit; SamplerSettings)"""
    inner_steps: int = 2
    """joint data updates of map, materials and exposure per reverse step"""
    lr_map: float = 0.05
    """Adam rate of the map's log radiance per data update"""
    prox_weight: float = 0.5
    """weight of ||z - x0_hat||^2 per unit abar_t / (1 - abar_t)"""
    noise_mix: float = 0.5
    """share zeta of fresh noise in the re-noising (0: deterministic DDIM, 1: all fresh)"""
    material_start: float = 0.3
    """fraction of the steps before the materials start to move"""

    models_sun = True


def rendered_views(run: DPSRun, env: torch.Tensor, state: DPSState, views: list[int], seed: int) -> list[torch.Tensor]:
    """The data term's renders of `views` (each with its own seed, at the sampler's spp)."""
    return [run.problem.render(env, state.materials, v, seed * 1009 + j, run.sampler.spp) for j, v in enumerate(views)]


def exposure_fit(run: DPSRun, renders: list[torch.Tensor], views: list[int]) -> float:
    """The least-squares global scale c of the renders against the images over their foreground: the
    renderer is linear in the map, so this is the exposure's exact optimum for the current map."""
    num = den = 0.0
    for rendered, v in zip(renders, views):
        mask = run.problem.masks[v].reshape(*rendered.shape[:-1], 1).to(rendered.dtype)
        num += float((mask * rendered * run.problem.images[v]).sum())
        den += float((mask * rendered.square()).sum())
    c = num / den if den > 0 and math.isfinite(num / den) and num > 0 else 1.0
    return min(max(c, math.exp(-MAX_EXPOSURE_STEP)), math.exp(MAX_EXPOSURE_STEP))


def recentre_(log_map: torch.Tensor, median_target: float) -> float:
    """Shift the map's log radiance so its median luminance is the prior's (in place); returns the shift
    for the exposure to take over. Map level and exposure are one degree of freedom: without this the
    level drifts and the encoded map saturates."""
    with torch.no_grad():
        shift = float(torch.log(luminance(torch.exp(log_map[0]).permute(1, 2, 0)).median() / median_target))
        log_map -= shift
    return shift


def relative_data_loss(run: DPSRun, renders: list[torch.Tensor], views: list[int], c: float) -> torch.Tensor:
    """Mean foreground loss of the renders times c over the mean squared foreground radiance: ~1 / SNR."""
    return sum(run.problem.view_loss(c * r, v) for r, v in zip(renders, views)) / (len(views) * run.data_norm)


def proximal_step(run: DPSRun, state: DPSState, n: int) -> dict[str, Any]:
    """x0_hat, `inner_steps` joint data updates of (map, materials, exposure) near it, stochastic re-noising."""
    settings: ProximalSettings = run.sampler
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
    abar = float(run.diffusion.alphas_cumprod[i])
    abar_prev = float(run.diffusion.alphas_cumprod_prev[i])
    prox_weight = settings.prox_weight * abar / (1.0 - abar)
    materials_move = n >= settings.material_start * run.num_steps
    if n == 0:
        floor = DARK_FLOOR * run.prior.median_target
        with torch.no_grad():
            state.log_map.copy_(torch.log(encoding.to_radiance(x0_hat).clamp_min(floor)))
    losses, skipped = [], 0
    for k in range(settings.inner_steps):
        views = run.views(gen)
        env = run.env(torch.exp(state.log_map), state)
        renders = rendered_views(run, env, state, views, run.render_seed(n, k))
        c = exposure_fit(run, [r.detach() for r in renders], views)
        state.log_exposure += math.log(c)
        data = relative_data_loss(run, renders, views, c)
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
        if not materials_move:
            for _, t in state.materials.items():
                t.grad = None
        state.optimizer.step()
        state.materials.clamp_()
        wrap_uv_(state.sun_uv)
        shift = recentre_(state.log_map, run.prior.median_target)
        state.log_exposure += shift
        with torch.no_grad():
            state.sun_log -= shift
        losses.append(float(data.detach()))
    laps.lap("render")
    with torch.no_grad():
        z = encoding.to_prior(torch.exp(state.log_map))
        eps_hat = (state.x - abar ** 0.5 * z) / (1.0 - abar) ** 0.5
        noise = torch.randn(z.shape, generator=gen)
        mixed = (1.0 - settings.noise_mix) ** 0.5 * eps_hat + settings.noise_mix ** 0.5 * noise
        state.x = abar_prev ** 0.5 * z + (1.0 - abar_prev) ** 0.5 * mixed
    return {**record, "loss": losses[-1] if losses else None, "prox": float(prox.detach()), "prox_weight": prox_weight,
            "log_exposure": float(state.log_exposure), "nan_inner": skipped,
            **({"skipped": "non-finite loss or gradient"} if not losses else {}), **laps.record()}
