"""How much better one reading explains the training views than another, relative to the views' noise.

A fit's data loss mixes two things: its misfit (what its light and materials cannot explain, the capture's own noise
included) and the variance of its renders (Monte Carlo noise, larger for a rough object's diffuse light than for a
mirror's lobe). The second says nothing about the reading, so the readings are compared by the misfit alone: each view
is rendered twice with independent seeds, and the product of the two residuals has the misfit as its mean (the
renders' noise cancels, as in dpi.solve.transport's halves). The difference of two readings' products, per pixel, has a
mean (how much better one explains the views) and a standard error, taken over blocks of each view (neighbouring
pixels share their errors); their ratio z gives the probability that the glossy reading explains the views better.
"""

from __future__ import annotations

import math

import torch

from dpi.solve.materials import MaterialTextures
from dpi.solve.problem import InverseProblem, to_loss_space

GRID = 8
"""each view is cut into GRID x GRID blocks, the units whose spread gives the difference's standard error"""


def normal_cdf(x: float) -> float:
    """The standard normal distribution function."""
    return 0.5 * (1.0 + math.erf(x / math.sqrt(2.0)))


def block_index(height: int, width: int) -> torch.Tensor:
    """(height, width) the block (of GRID x GRID) each pixel belongs to."""
    rows = torch.arange(height) * GRID // height
    cols = torch.arange(width) * GRID // width
    return rows[:, None] * GRID + cols[None, :]


def residual_products(problem: InverseProblem, env: torch.Tensor, materials: MaterialTextures, view: int,
                      seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """(h, w) the product of two independent renders' residuals (loss space, mean over the channels; its mean is
    the misfit) and the renders' noise ((a - b)^2 / 2, the same)."""
    target = to_loss_space(problem.images[view])
    first, second = (to_loss_space(problem.render(env, materials, view, seed + k)) - target for k in (0, 1))
    return (first * second).mean(-1), (first - second).square().mean(-1) / 2


def paired_difference(differences: list[torch.Tensor], masks: list[torch.Tensor]) -> tuple[float, float, int]:
    """The mean of per-pixel differences (one (h, w) map per view) over the masks' pixels, its standard error from
    the spread of the views' GRID x GRID block means (each weighted by its pixels), and the number of blocks."""
    blocks, weights = [], []
    for difference, mask in zip(differences, masks):
        index = block_index(*mask.shape)[mask]
        total = torch.zeros(GRID * GRID, dtype=torch.float64).index_add_(0, index, difference[mask].double())
        pixels = torch.zeros(GRID * GRID, dtype=torch.float64).index_add_(0, index, torch.ones_like(total[index]))
        seen = pixels > 0
        blocks.append(total[seen] / pixels[seen])
        weights.append(pixels[seen])
    means, weight = torch.cat(blocks), torch.cat(weights)
    mean = float((means * weight).sum() / weight.sum())
    spread = float(((means - mean).square() * weight).sum() / weight.sum())
    return mean, math.sqrt(spread / max(len(means) - 1, 1)), len(means)


def reading_evidence(problem: InverseProblem, fits: dict[str, tuple[torch.Tensor, MaterialTextures]],
                     seed: int) -> dict:
    """The rough and glossy fits' misfit and render noise over the training views' foreground, and z and p_glossy:
    the glossy minus rough misfit over its standard error, and the probability that the glossy reading explains the
    views better (normal_cdf(-z))."""
    sums = {name: {"misfit": 0.0, "noise": 0.0} for name in fits}
    differences, masks = [], []
    with torch.no_grad():
        for j, view in enumerate(problem.train_ids):
            mask = problem.masks[view]
            products = {}
            for name, (env, materials) in fits.items():
                products[name], noise = residual_products(problem, env, materials, view, seed * 1009 + 2 * j)
                sums[name]["misfit"] += float(products[name][mask].sum())
                sums[name]["noise"] += float(noise[mask].sum())
            differences.append(products["glossy"] - products["rough"])
            masks.append(mask)
    mean, error, blocks = paired_difference(differences, masks)
    z = mean / error if error > 0 else 0.0  # no spread over the blocks: identical fits
    count = max(sum(int(mask.sum()) for mask in masks), 1)
    record = {name: {key: value / count for key, value in parts.items()} for name, parts in sums.items()}
    return {**record, "z": z, "p_glossy": normal_cdf(-z), "blocks": blocks}
