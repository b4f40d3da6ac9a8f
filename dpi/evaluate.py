"""Evaluation of decompositions: per-sample metrics and the summary over samples, methods, scenes.

A metric that cannot be computed (no held-out views, no ground truth) is recorded as
`"missing: <reason>"`, never as a number.
"""

from __future__ import annotations

import csv
import json
import math
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dpi.atomic import atomic_path
from dpi.exr import read_exr
from dpi.images import linear_to_srgb
from dpi.metrics import albedo_mse, env_metrics, normalized_env, psnr, sample_variance, ssim
from dpi.solve.decomposition import Decomposition
from dpi.solve.problem import InverseProblem

NOVEL_VIEW_NOTE = "held-out views, sRGB-encoded, foreground pixels (PSNR) / masked image (SSIM)"


def missing(reason: str) -> str:
    """The value recorded for a metric that could not be computed."""
    return f"missing: {reason}"


def novel_view_metrics(problem: InverseProblem, decomposition: Decomposition, spp: int, seed: int) -> dict[str, Any]:
    """Mean PSNR/SSIM of re-rendered held-out views against the captured ones."""
    if not problem.held_out_ids:
        return {"novel_psnr": missing("no held-out views"), "novel_ssim": missing("no held-out views")}
    psnrs, ssims = [], []
    for view in problem.held_out_ids:
        with torch.no_grad():
            rendered = problem.render(decomposition.env, decomposition.materials, view, seed + view, spp).numpy()
        mask = problem.masks[view].numpy()
        a = linear_to_srgb(rendered) * mask[..., None]
        b = linear_to_srgb(problem.images[view].numpy()) * mask[..., None]
        psnrs.append(psnr(a, b, mask))
        ssims.append(ssim(a, b))
    return {"novel_psnr": float(np.mean(psnrs)), "novel_ssim": float(np.mean(ssims))}


def ground_truth_metrics(decomposition: Decomposition, gt: dict[str, Path]) -> dict[str, Any]:
    """Env-map PSNR/SSIM and albedo MSE against ground-truth files, when present."""
    out: dict[str, Any] = {}
    if "envmap" in gt:
        out.update(env_metrics(decomposition.env.numpy(), read_exr(gt["envmap"])))
    else:
        out.update({k: missing("no gt/envmap.exr") for k in ("env_psnr", "env_ssim")})
    if "albedo" in gt:
        mse, scales = albedo_mse(decomposition.materials.albedo.numpy(), read_exr(gt["albedo"]))
        out.update({"albedo_mse": mse, "albedo_scale": [float(s) for s in scales]})
    else:
        out["albedo_mse"] = missing("no gt/albedo.exr")
    return out


def evaluate_sample(problem: InverseProblem, decomposition: Decomposition, spp: int, seed: int,
                    seconds: float | None) -> dict[str, Any]:
    """All per-sample metrics of one decomposition."""
    return {**novel_view_metrics(problem, decomposition, spp, seed),
            **ground_truth_metrics(decomposition, problem.capture.gt),
            "sample_seconds": seconds if seconds is not None else missing("no trace"),
            "notes": {"novel_view": NOVEL_VIEW_NOTE,
                      "env": "global log-luminance scale alignment, Reinhard tone map",
                      "albedo": "per-channel least-squares scale alignment"}}


SUMMARY_METRICS = ("novel_psnr", "novel_ssim", "env_psnr", "env_ssim", "albedo_mse", "sample_seconds")


def _mean_std(values: list[Any]) -> tuple[Any, Any]:
    """Mean and std of the numeric values; a missing-reason string if none is numeric."""
    numbers = [v for v in values if isinstance(v, (int, float)) and math.isfinite(v)]
    if not numbers:
        reasons = sorted({v for v in values if isinstance(v, str)})
        return (reasons[0] if reasons else missing("no samples")), ""
    return float(np.mean(numbers)), float(np.std(numbers))


def summarize(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per (scene, method): metric means/stds, sigma2_sample of env and albedo, timings.

    Each record has scene, method, sample, metrics (dict) and sample_dir (Path); `sample_seconds` is
    the wall time of the job that made the sample (for method `init`, the initialisation).
    """
    groups: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for r in records:
        groups[(r["scene"], r["method"])].append(r)
    rows = []
    for (scene, method), recs in sorted(groups.items()):
        row: dict[str, Any] = {"scene": scene, "method": method, "samples": len(recs)}
        for name in SUMMARY_METRICS:
            row[name], row[f"{name}_std"] = _mean_std([r["metrics"].get(name) for r in recs])
        envs = [normalized_env(read_exr(Path(r["sample_dir"]) / "envmap.exr")) for r in recs]
        albedos = [_normalized_albedo(read_exr(Path(r["sample_dir"]) / "albedo.exr")) for r in recs]
        row["env_sigma2_sample"] = sample_variance(envs) if len(recs) > 1 else missing("one sample")
        row["albedo_sigma2_sample"] = sample_variance(albedos) if len(recs) > 1 else missing("one sample")
        rows.append(row)
    return rows


def _normalized_albedo(albedo: np.ndarray) -> np.ndarray:
    """Albedo divided by its mean (scale-free, for spread across samples)."""
    return albedo / max(float(albedo.mean()), 1e-6)


def write_csv(path: str | Path, rows: list[dict[str, Any]]) -> None:
    """Write rows (union of their keys as columns, first-seen order) as CSV, atomically."""
    columns: list[str] = []
    for row in rows:
        columns += [k for k in row if k not in columns]
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _cell(row.get(k, "")) for k in columns})


def _cell(value: Any) -> Any:
    """CSV cell: floats rounded to 6 significant digits, lists as JSON."""
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, (list, dict)):
        return json.dumps(value)
    return value
