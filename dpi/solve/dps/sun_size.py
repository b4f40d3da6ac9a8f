"""The written sun's angular size: the one the training views favour, path traced.

The data term sees the map on the transport's grid, where a sun is one blurred texel: it fits the sun's direction and
energy, not its size. Written as the real sun's 0.53 deg disc, a sun that the views saw as a broad highlight (a light
source larger than the sun, a procedural world's sun texel) renders a glossy object's highlight far brighter and
narrower than the photos show. So before the refinement each candidate radius, from the sun's own up to a texel of
the prior's map, is path traced over the training views (the loop's materials, two seeds each): the smallest radius
whose loss is within two noise deviations of the best one is written, the sun's own wherever the views cannot tell (a
rough object).
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np
import torch

from dpi.light.sunlight import SUN_RADIUS_DEG
from dpi.solve.materials import MaterialTextures
from dpi.solve.problem import InverseProblem

def sun_radii(prior_rows: int) -> list[float]:
    """The radii tried (deg): the sun's own, doubled while at most one texel of the prior's map (180 / rows deg); a
    broader light is the prior's sky's to hold."""
    radii = [SUN_RADIUS_DEG]
    while 2 * radii[-1] <= 180.0 / prior_rows:
        radii.append(2 * radii[-1])
    return radii
SIZE_VIEWS = 8
"""most training views rendered per radius (evenly spread over them)"""
NOISE_DEVIATIONS = 2.0
"""a larger radius is written only when its loss is below the sun's own by more than this many noise deviations"""


def size_views(problem: InverseProblem) -> list[int]:
    """Up to SIZE_VIEWS training views, evenly spread over them."""
    ids = problem.train_ids
    if len(ids) <= SIZE_VIEWS:
        return list(ids)
    return [ids[int(i)] for i in np.linspace(0, len(ids) - 1, SIZE_VIEWS).round()]


def views_sun_radius(problem: InverseProblem, env_with_sun: Callable[[float], torch.Tensor],
                     materials: MaterialTextures, seed: int, prior_rows: int) -> tuple[float, dict[str, float]]:
    """The radius (deg) to write the sun with (module notes) among `sun_radii(prior_rows)`, and each candidate's mean
    loss; `env_with_sun(r)` is the sample's map with its sun drawn at radius r."""
    candidates = sun_radii(prior_rows)
    views = size_views(problem)
    losses, noise = {}, []
    with torch.no_grad():
        for radius in candidates:
            env = env_with_sun(radius)
            pair = [float(problem.data_loss(env, materials, views, seed + k)) for k in (0, 1)]
            losses[radius] = (pair[0] + pair[1]) / 2
            noise.append((pair[0] - pair[1]) ** 2 / 4)  # the variance of the pair's mean
    deviation = math.sqrt(sum(noise) / len(noise))
    best = min(losses.values())
    chosen = next(r for r in candidates if losses[r] <= best + NOISE_DEVIATIONS * deviation)
    return chosen, {f"{r:g}": round(v, 8) for r, v in losses.items()}
