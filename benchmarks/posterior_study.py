"""Posterior-sampling study: every method and every dps sampler over scenes and seeds (issue 16).

Scenes are synthetic captures with ground truth, built from illuminations the priors never saw
(procedural maps from the evaluation seed stream, Mitsuba's sunsky). The `ambiguous` group is
where the paper shows a prior's worth: rough dielectric objects seen from few views on a limited
arc, under a sun map, an indoor room and a map clipped to the paper's tone-curve range (like its
8-bit test panoramas). The `glossy` group is a shiny metal object seen from all around, where a
free fit already recovers the light and a prior can only tie. Each scene gets one initialisation;
each method then draws one sample per seed through the workflow's own stage functions
(dpi.stages) with config.yaml's settings (preset applied), and the workflow's evaluation scores it.

    .venv/bin/python benchmarks/posterior_study.py [--scenes ...] [--methods ...] [--seeds 0 1 2] [--jobs 2]

Rows go to benchmarks/results/posterior_study.csv (one per scene, method, sampler, seed; rows
already there are kept and not rerun, so an interrupted study continues), then it prints mean +-
std per group, method and sampler. `--dps NAME:key=value,...` adds a dps variant (dev studies).
"""

from __future__ import annotations

import argparse
import csv
import json
import multiprocessing
import os
import shutil
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from dpi.layout import Layout

ROOT = Path(__file__).resolve().parent.parent
WORK = ROOT / "results" / "benchmarks" / "posterior_study"
CSV = ROOT / "benchmarks" / "results" / "posterior_study.csv"
METRICS = ("novel_psnr", "env_psnr", "env_ssim", "albedo_mse", "relight_psnr_h", "relight_psnr_l", "relight_ssim")
"""the workflow's sample metrics a study row keeps"""
COLUMNS = ("scene", "group", "method", "sampler", "seed", *METRICS, "seconds")
SIZE = {"views": 8, "held_out_every": 4, "width": 32, "height": 32, "spp": 128, "env_height": 32,
        "texture_size": 32}
AMBIGUOUS = {**SIZE, "roughness": 0.7, "roughness_variation": 0.1, "metallic": 0.0, "arc_deg": 150.0,
             "elevations_deg": (15.0, 40.0)}
GLOSSY = {**SIZE, "roughness": 0.08, "roughness_variation": 0.0, "metallic": 1.0, "arc_deg": 360.0}
SCENES: dict[str, tuple[str, dict[str, Any]]] = {
    "blob_sun": ("ambiguous", {**AMBIGUOUS, "shape": "blob", "seed": 0, "environment": "outdoor",
                               "environment_seed": 11, "prior": "outdoor"}),
    "blob_room": ("ambiguous", {**AMBIGUOUS, "shape": "blob", "seed": 0, "environment": "indoor",
                                "environment_seed": 12, "prior": "indoor"}),
    "blob_ldr": ("ambiguous", {**AMBIGUOUS, "shape": "blob", "seed": 0, "environment": "outdoor",
                               "environment_seed": 13, "environment_clip": 5.3, "prior": "outdoor"}),
    "torus_sun": ("ambiguous", {**AMBIGUOUS, "shape": "bumpy_torus", "seed": 3, "environment": "sunsky",
                                "sun_elevation_deg": 25.0, "sun_azimuth_deg": 200.0, "prior": "outdoor"}),
    "torus_room": ("ambiguous", {**AMBIGUOUS, "shape": "bumpy_torus", "seed": 3, "environment": "indoor",
                                 "environment_seed": 14, "prior": "indoor"}),
    "torus_ldr": ("ambiguous", {**AMBIGUOUS, "shape": "bumpy_torus", "seed": 3, "environment": "outdoor",
                                "environment_seed": 15, "environment_clip": 5.3, "prior": "outdoor"}),
    "blob_glossy": ("glossy", {**GLOSSY, "shape": "blob", "seed": 5, "environment": "outdoor",
                               "environment_seed": 16, "prior": "outdoor"}),
}
METHODS = ("init", "none", "smoothness", "sds", "dip", "dps")
TEXT_COLUMNS = ("scene", "group", "method", "sampler")


@dataclass(frozen=True)
class Job:
    """One sample to draw and score, in study folder `root`."""

    root: Path
    scene: str
    group: str
    synth: dict
    method: str
    sampler: str
    seed: int
    method_cfg: dict
    config: dict
    rerun: bool = False

    @property
    def label(self) -> str:
        """The method's folder: the method, with the dps sampler's label."""
        return self.method if not self.sampler else f"{self.method}_{self.sampler}"

    @property
    def layout(self) -> Layout:
        """The study's results and captures, in the workflow's layout."""
        return study_layout(self.root)

    @property
    def sample_dir(self) -> Path:
        """Where the sample is (the init's folder for the init row)."""
        return self.layout.scene(self.scene).sample_dir(self.label, self.seed)


def study_layout(root: Path) -> Layout:
    """A study folder holds captures/ and results/ like a workflow run."""
    return Layout(root / "results", root / "captures")


STUDY_TEXTURES = 32
"""texture size of the study problems: the views are 32 px, so the default's 64 would not be seen"""


def workflow_config(env_height: int | None = None) -> dict[str, Any]:
    """The workflow's resolved config (defaults and preset) with the study's texture size, the map at the preset's
    size (or `env_height` rows: the calibration and sun studies' tables were drawn at 16)."""
    from dpi.pipeline import resolve_config

    sizes = {"texture_size": STUDY_TEXTURES, **({"env_height": env_height} if env_height else {})}
    return resolve_config({"problem": sizes})


def prepare_capture(root: Path, scene: str, synth: dict, threads: int) -> Path:
    """The scene's capture and validated capture.json (made once, then reused); the latter's path."""
    from dpi.stages import capture_stage
    from dpi.synth.capture import SynthConfig, make_synthetic_capture

    layout = study_layout(root)
    files = layout.scene(scene)
    if not layout.synth_marker(scene).exists():
        make_synthetic_capture(layout.capture_dir(scene), SynthConfig.from_dict(synth), threads=threads,
                               progress=False)
    if not files.capture_json.exists():
        capture_stage(layout.capture_dir(scene), files.capture_json)
    return files.capture_json


def prepare_scene(root: Path, scene: str, synth: dict, config: dict, threads: int) -> None:
    """The scene's capture, validated capture.json and initialisation (made once, then reused)."""
    from dpi.stages import SolveSettings, init_stage

    prepare_capture(root, scene, synth, threads)
    files = study_layout(root).scene(scene)
    if not files.sample_files("init")["trace"].exists():
        init_stage(files.capture_json, files.sample_dir("init"), scene, config["init"],
                   SolveSettings.from_config(config, threads), progress=False)


def prepare_job(job: Job) -> None:
    """prepare_scene for a job's scene (a pool task)."""
    prepare_scene(job.root, job.scene, job.synth, job.config, threads=2)


def run_job(job: Job) -> dict[str, Any]:
    """Draw (except for init) and evaluate one sample; the row of the CSV."""
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    from dpi.stages import SolveSettings, evaluate_stage, sample_stage

    files, sample_dir = job.layout.scene(job.scene), job.sample_dir
    settings = SolveSettings.from_config(job.config, threads=1)
    if job.rerun and job.method != "init":
        shutil.rmtree(sample_dir, ignore_errors=True)
    if job.method != "init" and not files.sample_files(job.label, job.seed)["trace"].exists():
        sample_stage(files.capture_json, files.sample_dir("init"), sample_dir, job.scene, job.method, job.seed,
                     job.method_cfg, settings, progress=False)
    out = files.evaluation(job.label, job.seed)
    evaluate_stage(files.capture_json, sample_dir, out, job.scene, job.method, job.seed,
                   job.config["evaluate"]["spp"], settings)
    metrics = json.loads(out.read_text())["metrics"]
    return {"scene": job.scene, "group": job.group, "method": job.method, "sampler": job.sampler,
            "seed": job.seed, **{k: metrics[k] for k in METRICS},
            "seconds": metrics["sample_seconds"]}


def job_settings(settings: dict) -> dict:
    """A method's settings as one sample job takes them: without the workflow's sample count."""
    return {k: v for k, v in settings.items() if k != "samples"}


def dps_variants(config: dict, extra: list[str]) -> dict[str, dict]:
    """dps settings per sampler label: each built-in sampler, plus `NAME:key=value,...` variants (a dotted key
    names a section's setting: `proximal.inner_steps=4`)."""
    from dpi.pipeline import merge
    from dpi.solve.dps import SAMPLERS

    base = config["method_params"].get("dps", {})
    variants = {name: {**base, "sampler": name} for name in SAMPLERS}
    for spec in extra:
        name, _, pairs = spec.partition(":")
        values: dict = {}
        for key, value in (p.split("=", 1) for p in pairs.split(",") if p):
            *sections, leaf = key.split(".")
            node = values
            for section in sections:
                node = node.setdefault(section, {})
            node[leaf] = yaml.safe_load(value)
        variants[name] = merge(base, values)
    return variants


def jobs_for(args: argparse.Namespace, config: dict, root: Path = WORK,
             scenes: dict[str, tuple[str, dict]] = SCENES) -> list[Job]:
    """Every (scene, method, sampler, seed) asked for."""
    variants = dps_variants(config, args.dps)
    jobs = []
    for scene in args.scenes:
        for method in args.methods:
            labels = {v: cfg for v, cfg in variants.items() if v in (args.samplers or variants)} \
                if method == "dps" else {"": config["method_params"].get(method, {})}
            for sampler, cfg in labels.items():
                cfg = job_settings(cfg)
                seeds = [0] if method == "init" else args.seeds
                group, synth = scenes[scene]
                jobs.extend(Job(root, scene, group, synth, method, sampler, s, cfg, config, args.rerun) for s in seeds)
    return jobs


def read_rows(path: Path, text: tuple[str, ...] = TEXT_COLUMNS) -> list[dict[str, Any]]:
    """Rows of a study CSV (numbers parsed, except the `text` columns)."""
    if not path.exists():
        return []
    with open(path, newline="") as f:
        return [{k: (v if k in text else number(v)) for k, v in row.items()} for row in csv.DictReader(f)]


def number(value: str) -> float | str:
    """A CSV cell as a number, or as it is when it is none (a metric reported `missing: <reason>`)."""
    try:
        return float(value)
    except ValueError:
        return value


def append_row(path: Path, row: dict[str, Any], columns: tuple[str, ...] = COLUMNS) -> None:
    """Add one row (with a header when the file is new)."""
    new = not path.exists()
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        if new:
            writer.writeheader()
        writer.writerow({k: row[k] for k in columns})


def mean_std_cells(rows: list[dict[str, Any]], metrics: tuple[tuple[str, str], ...]) -> list[str]:
    """`mean +- std` over the rows of each (column, format) in `metrics`, for a summary table."""
    cells = []
    for key, fmt in metrics:
        values = np.asarray([r[key] for r in rows], dtype=float)
        cells.append(f"{values.mean():{fmt}} +- {values.std():{fmt}}")
    return cells


def summary(rows: list[dict[str, Any]]) -> list[str]:
    """Mean +- std per group, method and sampler over scenes and seeds (a relighting cell only where every row has
    the metric: rows of studies before it have none)."""
    shown = (("novel_psnr", ".2f"), ("env_psnr", ".2f"), ("env_ssim", ".3f"), ("albedo_mse", ".4f"),
             ("relight_psnr_h", ".2f"), ("relight_psnr_l", ".2f"), ("seconds", ".1f"))
    lines = [f"{'group':<10} {'method':<12} {'sampler':<12} {'n':>3} " + " ".join(f"{name:>17}" for name, _ in shown)]
    keys = sorted({(r["group"], r["method"], r["sampler"]) for r in rows},
                  key=lambda k: (k[0], METHODS.index(k[1]) if k[1] in METHODS else 99, k[2]))
    for group, method, sampler in keys:
        sel = [r for r in rows if (r["group"], r["method"], r["sampler"]) == (group, method, sampler)]
        cells = [mean_std_cells(sel, ((name, fmt),))[0] if all(isinstance(r.get(name), float) for r in sel) else "-"
                 for name, fmt in shown]
        lines.append(f"{group:<10} {method:<12} {sampler:<12} {len(sel):>3} " + " ".join(f"{c:>17}" for c in cells))
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", nargs="*", default=list(SCENES), choices=list(SCENES))
    parser.add_argument("--methods", nargs="*", default=list(METHODS), choices=list(METHODS))
    parser.add_argument("--samplers", nargs="*", default=None, help="dps sampler labels to run (default: all)")
    parser.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2])
    parser.add_argument("--dps", nargs="*", default=[], metavar="NAME:key=value,...", help="extra dps variants")
    parser.add_argument("--jobs", type=int, default=2, help="samples drawn side by side (1 thread each)")
    parser.add_argument("--out", type=Path, default=CSV, help="study CSV (rows already there are not rerun)")
    parser.add_argument("--rerun", action="store_true", help="redo rows already in the CSV (their samples too)")
    parser.add_argument("--work", type=Path, default=WORK,
                        help="study folder: captures, inits and samples (another folder: other inits, dev studies)")
    args = parser.parse_args()

    config = workflow_config()
    jobs = jobs_for(args, config, args.work)
    rows = run_study(jobs, args.out, COLUMNS, run_job, args.jobs)
    print("\n".join(summary(rows)))


def job_key(job: Job) -> tuple:
    """What tells a study's samples apart: scene, method, sampler, seed (a row's fields of the same names)."""
    return job.scene, job.method, job.sampler, job.seed


def row_key(row: dict[str, Any]) -> tuple:
    """`job_key` of a CSV row."""
    return row["scene"], row["method"], row["sampler"], int(row["seed"])


def run_study(jobs: list[Job], out: Path, columns: tuple[str, ...], score: Any, workers: int,
              keys: tuple[Any, Any] = (job_key, row_key), text: tuple[str, ...] = TEXT_COLUMNS) -> list[dict]:
    """Prepare every scene, draw and score the jobs whose rows `out` lacks (`score(job)` gives the row,
    appended as it comes), and return the rows of these jobs (`keys`: a job's and a row's key, equal when the
    row is the job's; `text`: the CSV's text columns)."""
    of_job, of_row = keys
    scenes = list({(j.root, j.scene): j for j in jobs}.values())
    # spawn, not fork: a forked child cannot use a GPU (cuda_ad_rgb) its parent already opened
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=max(1, min(workers, len(scenes))), mp_context=context) as pool:
        list(pool.map(prepare_job, scenes))
    done = {of_row(r) for r in read_rows(out, text)}
    todo = [j for j in jobs if j.rerun or of_job(j) not in done]
    print(f"{len(todo)} samples to draw and score ({len(done)} rows already in {out})", flush=True)
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        for row in pool.map(score, todo):
            append_row(out, row, columns)
            print("  ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()),
                  flush=True)
    wanted = {of_job(j) for j in jobs}
    return [r for r in read_rows(out, text) if of_row(r) in wanted]


if __name__ == "__main__":
    main()
