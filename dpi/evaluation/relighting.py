"""Relighting scored as the field scores it: the ground truth and a decomposition re-rendered under new light.

What a user does with a decomposition is relight the object, so a capture with ground-truth materials
(gt/albedo, roughness and metallic textures) is also scored this way: its held-out cameras render the
true materials and the sample's under each of RELIGHT_MAPS, and the sample's image is compared with the
truth's after a per-channel least-squares scale over the foreground (light and albedo trade a global
factor per channel; Stanford-ORB aligns the same way). Scores, averaged over maps and views:

- relight_psnr_h: PSNR of the linear HDR images, the peak being the truth's foreground maximum;
- relight_psnr_l: PSNR of the sRGB-encoded images clipped to [0, 1] (what a display shows), peak 1;
- relight_ssim: SSIM of those sRGB images, background set to 0.

The maps come from dpi's own generators, drawn from a seed stream of their own: no prior trained on them.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import numpy as np
import torch

from dpi.evaluation.metrics import missing, psnr, ssim
from dpi.evaluation.truth import true_materials
from dpi.io.images import linear_to_srgb
from dpi.render.renderer import Renderer
from dpi.solve.decomposition import Decomposition
from dpi.solve.problem import InverseProblem

RELIGHT_HEIGHT = 32
"""rows of the relighting maps (and of the renderer that lights with them)"""
RELIGHT_SEED_STREAM = 104_729
"""the maps draw from default_rng([this, seed]): neither a prior's training stream nor the evaluation's"""
RELIGHT_MAPS = {"outdoor_sun": ("outdoor", 5), "indoor": ("indoor", 1)}
"""name -> (generator family, seed): an outdoor sky whose sun holds 0.82 of its energy, and a room"""
RELIGHT_METRICS = ("relight_psnr_h", "relight_psnr_l", "relight_ssim")


@lru_cache(maxsize=None)
def relight_map(name: str) -> np.ndarray:
    """The (RELIGHT_HEIGHT, 2 RELIGHT_HEIGHT, 3) map `name` of RELIGHT_MAPS (drawn once per process)."""
    from dpi.worlds.families import generator

    family, seed = RELIGHT_MAPS[name]
    env = generator(family)(RELIGHT_HEIGHT, np.random.default_rng([RELIGHT_SEED_STREAM, seed]), 1)[0]
    return np.ascontiguousarray(env, np.float32)


def channel_scaled(estimate: np.ndarray, reference: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The estimate times the per-channel factor that best matches the reference over the mask (least squares)."""
    e, r = estimate[mask].astype(np.float64), reference[mask].astype(np.float64)
    scale = (e * r).sum(axis=0) / np.maximum((e * e).sum(axis=0), 1e-30)
    return estimate * scale


def relight_scores(estimate: np.ndarray, reference: np.ndarray, mask: np.ndarray) -> dict[str, float]:
    """PSNR-H, PSNR-L and SSIM of one relit view against the truth's (module notes); mask: the foreground."""
    aligned = channel_scaled(estimate, reference, mask)
    peak = max(float(reference[mask].max()), 1e-12)
    low_a = np.clip(linear_to_srgb(aligned), 0, 1) * mask[..., None]
    low_b = np.clip(linear_to_srgb(reference), 0, 1) * mask[..., None]
    return {"relight_psnr_h": psnr(aligned, reference, mask, data_range=peak),
            "relight_psnr_l": psnr(low_a, low_b, mask), "relight_ssim": ssim(low_a, low_b)}


def relit_name(light: str, view: str, truth: bool = False) -> str:
    """File stem of a relit held-out view in an evaluation's views folder (the truth's, or the sample's)."""
    return f"relit_{light}_{view}" + ("_truth" if truth else "")


def relight_held_out(problem: InverseProblem, decomposition: Decomposition, spp: int, seed: int
                     ) -> dict[str, np.ndarray] | str:
    """The held-out views of the sample's and of the true materials under each of RELIGHT_MAPS, by
    `relit_name` (linear; truth and sample rendered with one seed per map and view), or the missing-value
    saying why there are none."""
    if not problem.held_out_ids:
        return missing("no held-out views")
    size = decomposition.materials.albedo.shape[0]
    truth = true_materials(problem, size)
    if isinstance(truth, str):
        return truth
    renderer = Renderer(problem.capture.mesh, [problem.views[v].camera for v in problem.held_out_ids],
                        RELIGHT_HEIGHT, size, problem.renderer.settings)
    images = {}
    for m, light in enumerate(RELIGHT_MAPS):
        env = torch.from_numpy(relight_map(light))
        for i, view in enumerate(problem.held_out_ids):
            name = problem.views[view].name
            for materials, is_truth in ((decomposition.materials, False), (truth, True)):
                with torch.no_grad():
                    images[relit_name(light, name, is_truth)] = renderer.render(
                        env, materials.albedo, materials.roughness, materials.metallic, i, seed + 101 * m + i,
                        spp).numpy()
    return images


def relight_metrics(problem: InverseProblem, relit: dict[str, np.ndarray] | str) -> dict[str, Any]:
    """Mean relighting scores over RELIGHT_MAPS and the held-out views of `relight_held_out`'s images."""
    if isinstance(relit, str):
        return {name: relit for name in RELIGHT_METRICS}
    scores: dict[str, list[float]] = {name: [] for name in RELIGHT_METRICS}
    for light in RELIGHT_MAPS:
        for view in problem.held_out_ids:
            name = problem.views[view].name
            pair = relit[relit_name(light, name)], relit[relit_name(light, name, truth=True)]
            for key, value in relight_scores(*pair, problem.masks[view].numpy()).items():
                scores[key].append(value)
    return {key: float(np.mean(values)) for key, values in scores.items()}
