"""The summary over samples, methods and scenes (summary.csv, samples.csv): per (scene, method) the
means of the per-sample metrics, sigma2_sample of env and albedo, the spread maps' means and the samples'
calibration against the true map (dpi.solve.spread), env-map FID per method over all
scenes, and albedo sigma2_invar per (object, method) across the scenes (illuminations) of one object.
"""

from __future__ import annotations

import csv
import json
import math
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from dpi.capture import read_ground_truth
from dpi.evaluation.metric_table import split_missing
from dpi.evaluation.metrics import ENV_BALANCE, aligned_env, env_metrics, missing, resize_image
from dpi.evaluation.perceptual import (INCEPTION_WEIGHTS, azimuth_rolls, frechet_distance, inception_features,
                                       missing_weights, pretrained_inception)
from dpi.evaluation.relighting import RELIGHT_METRICS
from dpi.io.atomic import atomic_path
from dpi.io.exr import read_exr
from dpi.io.images import linear_to_srgb
from dpi.io.layout import ENV_FILE, INIT, texture_file
from dpi.solve.spread import (albedo_std_map, calibration, log_std_map, mean_log_map, normalized_albedo, normalized_env,
                        roughness_std_map, sample_variance, sphere_mean)

SUMMARY_METRICS = ("novel_psnr", "novel_ssim", "novel_lpips", "env_psnr", "env_ssim", *ENV_BALANCE, "env_lpips",
                   "env_niqe", "env_naturalness", "env_realism", "albedo_mse", "albedo_seam", *RELIGHT_METRICS,
                   "train_fit", "train_fit_over_truth", "sample_seconds")
SET_METRICS = ("env_fid", "albedo_sigma2_invar")
SPREAD_METRICS = ("env_log_std", "albedo_std", "roughness_std", "env_calibration", "env_mean_psnr", "env_mean_ssim",
                  *(f"env_mean_{name[4:]}" for name in ENV_BALANCE))


def _mean_std(values: list[Any]) -> tuple[Any, Any]:
    """Mean and std of the numeric values; a missing-reason string if none is numeric."""
    numbers = [v for v in values if isinstance(v, (int, float)) and math.isfinite(v)]
    if not numbers:
        reasons = sorted({v for v in values if isinstance(v, str)})
        return (reasons[0] if reasons else missing("no samples")), ""
    return float(np.mean(numbers)), float(np.std(numbers))


def summarize(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per (scene, method): metric means/stds, sigma2_sample of env and albedo, the set metrics
    (env FID of the method, albedo sigma2_invar of the object and method) and the scene's init seconds.

    Each record has scene, method, sample, metrics (dict), sample_dir (Path) and optionally object
    (default: the scene) and gt_envmap (path or None); `sample_seconds` is the wall time of the job that
    made the sample (for method `init`, the initialisation).
    """
    groups: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for r in records:
        groups[(r["scene"], r["method"])].append(r)
    init_seconds = {r["scene"]: r["metrics"].get("sample_seconds") for r in records if r["method"] == INIT}
    fid = env_fid(records)
    rows, mean_albedos = [], {}
    for (scene, method), recs in sorted(groups.items()):
        row: dict[str, Any] = {"scene": scene, "method": method, "sampler": samplers(recs),
                               "object": recs[0].get("object", scene), "samples": len(recs)}
        for name in SUMMARY_METRICS:
            row[name], row[f"{name}_std"] = _mean_std([r["metrics"].get(name) for r in recs])
        raw_envs = [read_exr(Path(r["sample_dir"]) / ENV_FILE) for r in recs]
        raw_albedos = [read_exr(Path(r["sample_dir"]) / texture_file("albedo")) for r in recs]
        roughness = [read_exr(Path(r["sample_dir"]) / texture_file("roughness")) for r in recs]
        envs = [normalized_env(e) for e in raw_envs]
        albedos = [normalized_albedo(a) for a in raw_albedos]
        row.update(spread_columns(raw_envs, raw_albedos, roughness, recs[0].get("gt_envmap")))
        row["env_sigma2_sample"] = sample_variance(envs) if len(recs) > 1 else missing("one sample")
        row["albedo_sigma2_sample"] = sample_variance(albedos) if len(recs) > 1 else missing("one sample")
        row["env_fid"] = fid[method]
        row["init_seconds"] = init_seconds.get(scene, missing("no init evaluation"))
        mean_albedos[(row["object"], method, scene)] = np.mean(albedos, axis=0)
        rows.append(row)
    invar = albedo_invariance(mean_albedos)
    for row in rows:
        row["albedo_sigma2_invar"] = invar[(row["object"], row["method"])]
    return rows


def spread_columns(envs: list[np.ndarray], albedos: list[np.ndarray], roughness: list[np.ndarray],
                   truth: str | Path | None) -> dict[str, Any]:
    """How far a method's samples spread (dpi.solve.spread): the mean of its uncertainty maps over the sphere and the
    textures, its calibration against the true map (~1: the truth looks like one more sample), and the env
    PSNR / SSIM of the samples' geometric mean map (what they agree on)."""
    if len(envs) < 2:
        return {name: missing("one sample") for name in SPREAD_METRICS}
    spread = {"env_log_std": sphere_mean(log_std_map(envs)), "albedo_std": float(albedo_std_map(albedos).mean()),
              "roughness_std": float(roughness_std_map(roughness).mean())}
    if not truth:
        return {**spread, **{name: missing("no gt/envmap.exr") for name in SPREAD_METRICS if name not in spread}}
    reference = read_ground_truth(truth, "envmap")
    mean = env_metrics(mean_log_map(envs), reference)
    return {**spread, "env_calibration": calibration(envs, reference),
            **{f"env_mean_{name[4:]}": mean[name] for name in ("env_psnr", "env_ssim", *ENV_BALANCE)}}


def samplers(records: list[dict[str, Any]]) -> str:
    """The dps sampler(s) that made a group's samples ("" for other methods; "a+b" if they differ)."""
    return "+".join(sorted({r.get("sampler", "") for r in records} - {""}))


def albedo_invariance(mean_albedos: dict[tuple[str, str, str], np.ndarray]) -> dict[tuple[str, str], Any]:
    """sigma2_invar per (object, method): the variance across the object's scenes (one illumination each)
    of the per-scene mean normalised albedo, given per (object, method, scene). Texels correspond only
    when the scenes share the mesh's UV layout; maps of another size are resampled to the first's."""
    per_object: dict[tuple[str, str], list[np.ndarray]] = defaultdict(list)
    for (obj, method, _), albedo in sorted(mean_albedos.items()):
        per_object[(obj, method)].append(albedo)
    return {(obj, method): missing(f"one illumination of object {obj}") if len(albedos) < 2
            else sample_variance([resize_image(a, *albedos[0].shape[:2]) for a in albedos])
            for (obj, method), albedos in per_object.items()}


def env_fid(records: list[dict[str, Any]]) -> dict[str, Any]:
    """FID per method between its samples' env maps (all scenes) and the scenes' ground-truth maps.

    Both enter as display images (scale-aligned, Reinhard, sRGB, at the estimate's resolution), each
    map as FID_ROLLS azimuth rotations: FID is a statistic of sets, and a scene has one ground truth.
    """
    methods = sorted({r["method"] for r in records})
    reason = missing_weights(INCEPTION_WEIGHTS)
    if reason:
        return {method: missing(reason) for method in methods}
    net = pretrained_inception()
    out: dict[str, Any] = {}
    for method in methods:
        estimates, references = [], {}
        for r in records:
            if r["method"] == method and r.get("gt_envmap"):
                a, b, _ = aligned_env(read_exr(Path(r["sample_dir"]) / ENV_FILE), read_ground_truth(r["gt_envmap"], "envmap"))
                estimates += azimuth_rolls(linear_to_srgb(a))
                references.setdefault(r["scene"], azimuth_rolls(linear_to_srgb(b)))
        out[method] = (frechet_distance(inception_features(estimates, net),
                                        inception_features([x for maps in references.values() for x in maps], net))
                       if estimates else missing("no gt/envmap.exr"))
    return out


def sample_rows(records: list[dict[str, Any]], summary: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per sample: its metrics, then the set metrics of its (scene, method) row of the summary."""
    sets = {(row["scene"], row["method"]): {k: row[k] for k in SET_METRICS} for row in summary}
    return [{"scene": r["scene"], "method": r["method"], "sampler": r.get("sampler", ""),
             "reading": r.get("reading", ""), "sample": r["sample"],
             **{k: v for k, v in r["metrics"].items() if k != "notes"}, **sets[(r["scene"], r["method"])]}
            for r in records]


def write_csv(path: str | Path, rows: list[dict[str, Any]]) -> None:
    """Write rows (union of their keys as columns, first-seen order) as CSV, atomically; a missing metric is an
    empty cell with its reason in the `notes` column, so every metric column reads as numbers."""
    rows = [split_missing(row) for row in rows]
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
