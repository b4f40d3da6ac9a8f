"""How well a decomposition re-renders the training views, next to how well the truth does: a posterior sample
and the truth are alike given the photos, so they should fit them about equally well.

The fit is the foreground mean squared error in the data term's loss space (InverseProblem.view_loss). A
re-render's own Monte Carlo noise would add its variance to that error and pull every ratio towards 1, so
each view is rendered twice with independent seeds and the error is the mean product of the two residuals,
whose expectation is the squared error of the expected render (the transport's two halves use the same
trick)."""

from __future__ import annotations

import numpy as np
import torch

from dpi.solve.decomposition import Decomposition
from dpi.solve.problem import InverseProblem, to_loss_space

SECOND_RENDER_SEED = 7919
"""seed offset of each view's second, independent render"""


def training_fit(problem: InverseProblem, decomposition: Decomposition, spp: int, seed: int) -> float:
    """Mean over the training views of the foreground squared error of the re-rendered view (loss space),
    without the renders' own noise (module notes); view v renders with seeds seed + v and that + an offset."""
    errors = []
    for v in problem.train_ids:
        target = to_loss_space(problem.images[v])
        mask = problem.masks[v][..., None].to(target.dtype)
        with torch.no_grad():
            first, second = (to_loss_space(problem.render(decomposition.env, decomposition.materials, v, s, spp))
                             for s in (seed + v, seed + v + SECOND_RENDER_SEED))
        errors.append(float((mask * (first - target) * (second - target)).sum() / (3 * mask.sum().clamp_min(1))))
    return float(np.mean(errors))
