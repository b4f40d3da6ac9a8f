"""The paper's sampler (Lyu et al. 2023; LinjieLyu/DPI condition_methods.py): gradient guidance on x_t.

eps from the randomly rolled x_t (paper Eq. 15), x0_hat by Tweedie, clamped; the gradient of
||y - R(L(x0_hat), k)|| w.r.t. x_t through renderer and network, bounded in max-abs, subtracted with
weight rho_t from the ancestral step; one Adam step on the materials from the same render. Tuned
for 1000 steps; it starts from pure noise and renders one view per step, as the reference.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from dpi.solve.dps.state import DPSRun, DPSState, Laps, finite, network_step
from dpi.solve.optimize import all_finite

GUIDANCE_BOUND = 0.1
"""max-abs of the rendering-loss gradient after rescaling"""
RHO = (0.1, 1.0)
"""guidance weight over the first half of the steps, and at the last step (linear in between), as the reference"""


@dataclass(frozen=True)
class PaperSampler:
    """The reference's fixed choices (no config section): from pure noise, one view per step, no parametric sun."""

    start_noise: float = 1.0
    views_per_step: int = 1
    models_sun: bool = False


def rho_schedule(n: int) -> np.ndarray:
    """Guidance weight per executed step (n steps, first executed = noisiest): RHO[0] over the first half, then
    linear to RHO[1]."""
    first = int(round(0.5 * n))
    rho = np.full(n, RHO[0])
    if n > first:
        rho[first:] = np.linspace(*RHO, n - first + 1)[1:]
    return rho


def scale_to_bound(g: torch.Tensor, bound: float) -> torch.Tensor:
    """g rescaled so that max|g| <= bound (unchanged when already inside)."""
    peak = float(g.abs().max())
    return g * (bound / peak) if peak > bound else g


def paper_step(run: DPSRun, state: DPSState, n: int) -> dict[str, Any]:
    """The paper's guided ancestral step (gradient through renderer and network, bounded, times rho_t)."""
    laps, i, gen = Laps(), run.index(n), state.generator
    rho = float(rho_schedule(run.num_steps)[n])
    x = state.x.detach().requires_grad_(True)
    p = network_step(run, x, i, gen)
    laps.lap("network")
    record = {"step": n, "t": int(run.diffusion.timestep_map[i]), "rho": rho}
    if not finite(p["mean"], p["log_variance"]):
        return {**record, "skipped": "non-finite network output", **laps.record()}  # keep x_t
    state.snapshots.append(p["x0"].detach()[0])
    env = run.env(run.prior.encoding.to_radiance(p["x0"]), state)
    env_leaf = env.detach().requires_grad_(True)
    loss = run.problem.residual_norm(env_leaf, state.materials, run.views(gen), seed=run.render_seed(n))
    state.optimizer.zero_grad()
    guided = finite(loss)
    if guided:
        loss.backward()
        laps.lap("render")
        env.backward(env_leaf.grad)
        laps.lap("network_backward")
        guided = x.grad is not None and finite(x.grad) and all_finite(list(dict(state.materials.items()).values()))
    with torch.no_grad():
        noise = torch.randn(x.shape, generator=gen) if i > 0 else torch.zeros_like(x)
        x_next = p["mean"] + torch.exp(0.5 * p["log_variance"]) * noise
        if guided:
            record["guidance_max"] = float(x.grad.abs().max())
            x_next = x_next - rho * scale_to_bound(x.grad, GUIDANCE_BOUND)
            state.optimizer.step()
            run.problem.constrain_(state.materials)
    state.x = x_next
    if not guided:
        record["skipped"] = "non-finite loss or gradient"
    return {**record, "loss": loss.item() if guided else None, **laps.record()}
