"""A global move for the proximal sampler: several arrangements of the light drawn side by side, the views choose.

A rough object's views fix the light's coarse balance but the prior places the bright sources (a room's windows,
a sun) in the first reverse steps, and no later local data step moves them (docs/studies.md, "the truth's own fit
as the yardstick"). So a sample starts `candidates` loop states from their own noise, runs them through the first
`select_at` of the schedule on the one shared recording of the light transport, and keeps the one whose map
explains the training views best once an albedo is fitted under it (the albedo is still grey then, and a fit under
grey would favour maps that paint the texture's pattern into the light). One resampling step of a particle filter
at zero temperature: each candidate is a draw of the sampler, the views' likelihood picks among them.
"""

from __future__ import annotations

import math
import time
from typing import Any, Callable

import torch

from dpi.seeding import seed_for
from dpi.solve.dps.data_term import current_level
from dpi.solve.dps.proximal import ProximalSettings, exposure_fit, relative_data_loss
from dpi.solve.dps.state import DPSRun, DPSState

ALBEDO_UPDATES = 30
"""Adam steps of a candidate's albedo under its map before it is scored"""
ALBEDO_RATE = 0.05
"""their rate (the albedo lives in [0, 1]: 30 steps can move it across its range)"""


def selection_step(run: DPSRun) -> int:
    """The executed step before which the candidates are compared (0: a single candidate, no selection)."""
    settings = run.sampler
    if getattr(settings, "candidates", 1) <= 1:
        return 0
    return max(1, min(run.num_steps - 1, round(settings.select_at * run.num_steps)))


def candidate_seed(seed: int, k: int) -> int:
    """The seed of candidate k of a sample (candidate 0 is the sample's own stream)."""
    return seed if k == 0 else seed_for(seed, "candidate", k)


def arrangement_fit(run: DPSRun, state: DPSState) -> float:
    """The relative data term of the state's map once an albedo is fitted under it (the state is not changed)."""
    transport = state.extra["transport"]
    level = current_level(transport, state.materials.roughness)
    with torch.no_grad():
        env = run.env(torch.exp(state.log_map), state, transport.height)
    albedo = state.materials.albedo.detach().clone().requires_grad_(True)
    optimizer = torch.optim.Adam([albedo], lr=ALBEDO_RATE)
    for _ in range(ALBEDO_UPDATES + 1):
        c = exposure_fit(transport, env, albedo.detach(), level)
        loss = relative_data_loss(run, transport, c * env, albedo, level)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        with torch.no_grad():
            albedo.clamp_(0.0, 1.0)
    value = float(loss.detach())
    return value if math.isfinite(value) else math.inf


def choose_arrangement(run: DPSRun, state: DPSState, new_state: Callable[[int], DPSState],
                       step: Callable[[DPSRun, DPSState, int], dict[str, Any]]) -> list[dict[str, Any]]:
    """Run `candidates` states (the sample's own and new_state(seed) for the others) through the steps before
    `selection_step`, sharing the first's recorded transport; make `state` the one whose views fit best and
    return its step records (the last one carries every candidate's score). Nothing to do with one candidate."""
    until = selection_step(run)
    if not until:
        return []
    settings: ProximalSettings = run.sampler
    states = [state] + [new_state(candidate_seed(run.seed, k)) for k in range(1, settings.candidates)]
    records: list[list[dict[str, Any]]] = [[] for _ in states]
    clock = time.perf_counter()
    for n in range(until):
        for k, candidate in enumerate(states):
            if k and "transport" in state.extra:
                candidate.extra.setdefault("transport", state.extra["transport"])
            records[k].append(step(run, candidate, n))
    scores = [arrangement_fit(run, candidate) for candidate in states]
    best = min(range(len(states)), key=scores.__getitem__)
    transport = state.extra.get("transport")
    vars(state).update(vars(states[best]))
    if transport is not None:
        state.extra["transport"] = transport
    chosen = records[best]
    chosen[0] = {**chosen[0], "refresh": records[0][0].get("refresh", False)}  # the shared recording was made once
    chosen[-1] = {**chosen[-1], "candidate": best, "candidate_fits": [round(s, 6) for s in scores],
                  "seconds_candidates": round(time.perf_counter() - clock, 4)}
    return chosen
