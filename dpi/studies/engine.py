"""The one engine the studies run on: a study is a list of jobs (scene, method, dps variant, seed), each drawn
and scored by the workflow's own stage functions (dpi.stages) on the job record a rule would build, into rows
of a CSV. What a study adds is only its scenes, repeats and the stamped rows.

Every row carries the commit it was made at and a hash of its resolved settings (the scene's synthetic
capture, the method's settings, the workflow sections a sample reads). A job's row is reused only when one
with the same key *and* settings hash is already in the CSV, so a rerun with other settings writes new rows
beside the old ones; the tables (benchmarks/doc_tables.py) show the newest row of each key (`latest`).
"""

from __future__ import annotations

import csv
import hashlib
import json
import multiprocessing
import os
import shutil
import subprocess
import sys
from collections import Counter
from collections.abc import Callable, Iterable
from concurrent.futures import Executor, ProcessPoolExecutor
from contextlib import nullcontext
from dataclasses import dataclass, replace
from functools import cache, cached_property
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from dpi.io.layout import INIT, Layout

PROVENANCE = ("commit", "settings_hash")
"""the columns every study row ends with"""
TEXT_COLUMNS = ("scene", "group", "method", "sampler", *PROVENANCE)
SAMPLE_METRICS = ("novel_psnr", "env_psnr", "env_ssim", "albedo_mse", "relight_psnr_h", "relight_psnr_l",
                  "relight_ssim", "train_fit", "train_fit_over_truth")
"""the workflow's sample metrics a study row keeps"""
SAMPLE_COLUMNS = ("scene", "group", "method", "sampler", "seed", *SAMPLE_METRICS, "seconds")
"""the columns of a row of one scored sample (run_job)"""
TEXT_SECTIONS = ("evaluate", "illumination_prior")
"""the workflow config sections a sample and its evaluation read as written (the renderer's, the problem's and the
init's are hashed as their settings dataclasses resolve them, so a default moved between a file and a dataclass
redraws nothing)"""
SETTINGS_STAMP = "study_settings_hash.txt"
"""a study sample's settings hash, in its folder: a sample drawn with other settings is drawn again"""
STUDY_TEXTURES = 32
"""texture size of the study problems: their views are 32 px, so the default's 64 would not be seen"""
CHECKOUT = Path(__file__).resolve().parents[2]
"""the checkout the studies run in (their folders and CSVs are the repository's)"""
CHECKOUT_LAYOUT = Layout(CHECKOUT / "results", CHECKOUT / "captures")
"""the checkout's own run, whose results hold the studies' folders"""


def work_dir(study: str) -> Path:
    """A study's folder of captures, inits and samples (not committed)."""
    return CHECKOUT_LAYOUT.study_dir(study)


def results_csv(study: str) -> Path:
    """A study's committed rows: benchmarks/STUDY/STUDY.csv (the study's folder)."""
    return CHECKOUT / "benchmarks" / study / f"{study}.csv"


def settings_hash(settings: Any) -> str:
    """A short, stable hash of JSON-able settings (key order does not matter)."""
    text = json.dumps(settings, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


@cache
def current_commit() -> str:
    """The checkout's commit (12 hex digits), `-dirty` when tracked files differ from it; `unknown` outside git."""
    root = Path(__file__).resolve().parents[2]
    try:
        head = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], cwd=root, capture_output=True, text=True,
                              check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=root,
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("-dirty" if dirty else "")


def sample_label(method: str, sampler: str) -> str:
    """A study sample's method folder: the method, with the dps variant's label."""
    return method if not sampler else f"{method}_{sampler}"


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
        """The method's folder (`sample_label`)."""
        return sample_label(self.method, self.sampler)

    @property
    def layout(self) -> Layout:
        return Layout.of_study(self.root)

    @cached_property
    def pipeline(self):
        """The workflow's pipeline of this one job: the study's config with the scene as its synthetic scene and
        the method's settings as its entry, results and captures in the study folder."""
        from dpi.config.pipeline import Pipeline

        layout = self.layout
        return Pipeline({**self.config, "results_dir": str(layout.results), "captures_dir": str(layout.captures),
                         "scenes": [self.scene], "synthetic": {self.scene: self.synth},
                         "method_params": {**self.config.get("method_params", {}), self.method: self.method_cfg}})

    def stage_job(self, threads: int = 1):
        """The stage job record of this sample (dpi.stages), as the workflow's rule builds it."""
        from dpi.stages import StageJob

        return StageJob(self.pipeline, self.scene, self.method, self.seed, threads=threads,
                        label=self.label if self.sampler else None, progress=False)

    @property
    def sample_dir(self) -> Path:
        """Where the sample is (the init's folder for the init row)."""
        return self.layout.scene(self.scene).sample_dir(self.label, self.seed)

    @property
    def settings_hash(self) -> str:
        """Hash of what decides the sample besides its seed: the capture (a panorama by its name and its
        content's digest), the method and its settings as it resolves them (its dataclass's defaults included,
        so a changed default redraws), the workflow sections a sample reads, and for a
        method that samples with the diffusion prior the prior file's content (a prior retrained under the same
        name draws its samples again)."""
        from dpi.solve.methods import REGISTRY
        from dpi.synth.capture import PROCEDURAL

        light = self.synth.get("environment")
        panorama = Path(light) if light and light not in PROCEDURAL else None
        digest = f"@{file_digest(panorama)}" if panorama and panorama.is_file() else ""
        synth = {**self.synth, **({"environment": panorama.name + digest} if panorama else {})}
        adaptive = {"adaptive": self.config["adaptive"]} if self.config.get("adaptive") else {}
        samples_prior = self.method in REGISTRY and REGISTRY[self.method].needs_prior and "illumination_prior" in \
            self.config
        checkpoint = Path(self.pipeline.prior_checkpoint(self.scene)) if samples_prior else None
        prior = {"prior": file_digest(checkpoint) if checkpoint.is_file() else str(checkpoint)} if checkpoint else {}
        settings = self.method_cfg
        if self.method in REGISTRY:
            from dpi.config.pipeline import plain
            from dpi.solve.methods import method_config

            settings = plain(method_config(self.method, self.method_cfg))
        return settings_hash({"synth": synth, "method": self.method, "settings": settings,
                              "config": self.resolved_sections(), **adaptive, **prior})

    def resolved_sections(self) -> dict[str, Any]:
        """What a sample reads of the workflow config besides its method's settings: the renderer's, problem's and
        init's settings as resolved (threads left out), and the TEXT_SECTIONS as written."""
        from dpi.config.pipeline import plain

        pipeline = self.pipeline
        solve = pipeline.solve_settings()
        return {"render": plain(solve.render), "problem": plain(solve.problem), "init": plain(pipeline.init_settings),
                **{k: self.config.get(k) for k in TEXT_SECTIONS}}


@cache
def file_digest(path: Path) -> str:
    """The first 16 hex digits of a file's SHA-256, once a process."""
    from dpi.prior.panoramas import sha256_of

    return sha256_of(path)[:16]


def prior_checkpoints(pairs: Iterable[str]) -> dict[str, str]:
    """A study's `--prior FAMILY=CHECKPOINT` pairs as config illumination_prior.checkpoints entries."""
    checkpoints = {}
    for pair in pairs:
        family, sep, checkpoint = pair.partition("=")
        if not sep or not checkpoint:
            raise ValueError(f"--prior {pair!r}: expected FAMILY=CHECKPOINT")
        checkpoints[family] = checkpoint
    return checkpoints


def workflow_config(env_height: int | None = None, texture_size: int = STUDY_TEXTURES) -> dict[str, Any]:
    """The workflow's resolved config (defaults and preset) with textures of `texture_size`, the map at the
    preset's size or at `env_height` rows."""
    from dpi.config.pipeline import resolve_config

    sizes = {"texture_size": texture_size, **({"env_height": env_height} if env_height else {})}
    return resolve_config({"problem": sizes})


def prepare_capture(root: Path, scene: str, synth: dict, threads: int) -> Path:
    """The scene's capture, validated capture.json and the atlas of a mesh given without UVs (made once, then
    reused), by the workflow's stages; capture.json's path."""
    from dpi.stages import capture_stage, preprocess_scene, synth_capture_stage

    job = Job(root, scene, "", synth, "init", "", 0, {}, workflow_config()).stage_job(threads)
    if not job.pipeline.layout.synth_marker(scene).exists():
        synth_capture_stage(job)
    if job.given["mesh_has_uv"]:
        if not job.paths.capture_json.exists():
            capture_stage(job)
    elif not job.paths.geometry["mesh_uv"].exists():
        preprocess_scene(job)
    return job.paths.capture_json


def prepare_job(job: Job) -> None:
    """A job's scene: capture, capture.json and initialisation (made once, then reused)."""
    from dpi.stages import init_stage

    prepare_capture(job.root, job.scene, job.synth, threads=2)
    if not job.layout.scene(job.scene).sample_files(INIT)["trace"].exists():
        init_stage(replace(job, method=INIT, sampler="").stage_job(threads=2))


def claim_sample_dir(job: Job) -> None:
    """Empty a sample's folder drawn with other settings (or when the job reruns), then stamp it with the job's
    settings hash before drawing, so a killed draw resumes under the same settings."""
    stamp = job.sample_dir / SETTINGS_STAMP
    if job.rerun or not stamp.is_file() or stamp.read_text() != job.settings_hash:
        shutil.rmtree(job.sample_dir, ignore_errors=True)
        job.sample_dir.mkdir(parents=True)
        stamp.write_text(job.settings_hash)


def run_job(job: Job) -> dict[str, Any]:
    """Draw (except for the init) and evaluate one sample; its row (SAMPLE_COLUMNS)."""
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    from dpi.stages import evaluate_stage, sample_stage

    stage = job.stage_job(threads=1)
    if job.method != INIT:
        claim_sample_dir(job)
        if not stage.paths.sample_files(job.label, job.seed)["trace"].exists():
            sample_stage(stage)
    evaluate_stage(stage)
    metrics = json.loads(stage.evaluation.read_text())["metrics"]
    return {"scene": job.scene, "group": job.group, "method": job.method, "sampler": job.sampler,
            "seed": job.seed, **{k: metrics[k] for k in SAMPLE_METRICS}, "seconds": metrics["sample_seconds"]}


def job_settings(settings: dict) -> dict:
    """A method's settings as one sample job takes them: without the workflow's sample count."""
    return {k: v for k, v in settings.items() if k != "samples"}


def dps_variants(config: dict, extra: list[str]) -> dict[str, dict]:
    """dps settings per sampler label: each built-in sampler, plus `NAME:key=value,...` variants (a dotted key
    names a section's setting: `proximal.inner_steps=4`)."""
    from dpi.config.pipeline import merge
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


def method_jobs(root: Path, scenes: dict[str, tuple[str, dict]], methods: Iterable[str], seeds: list[int],
                config: dict, variants: dict[str, dict], samplers: list[str] | None = None,
                rerun: bool = False) -> list[Job]:
    """Every (scene, method, dps variant, seed) of a study: `scenes` maps a name to (group, synthetic capture);
    the init gets seed 0 only; dps one job per variant in `samplers` (default: all of `variants`)."""
    jobs = []
    for scene, (group, synth) in scenes.items():
        for method in methods:
            labels = {v: cfg for v, cfg in variants.items() if v in (samplers or variants)} \
                if method == "dps" else {"": config["method_params"].get(method, {})}
            for sampler, cfg in labels.items():
                for seed in ([0] if method == "init" else seeds):
                    jobs.append(Job(root, scene, group, synth, method, sampler, seed, job_settings(cfg), config,
                                    rerun))
    return jobs


def study_workflow(jobs: list[Job], name: str) -> dict[str, Any]:
    """A study's scenes, methods, sample counts and settings as one workflow config (`snakemake --configfile`),
    in study folder NAME (`work_dir`): the same study with the workflow's report and logs. dps keeps its
    configured sampler only (a workflow has one dps), and the init is every workflow's own."""
    from dpi.io.settings import field_default
    from dpi.solve.dps import DPSConfig

    config = jobs[0].config
    sampler = config["method_params"].get("dps", {}).get("sampler", field_default(DPSConfig, "sampler"))
    plain = [j for j in jobs if j.method != INIT and j.sampler.split("@")[0] in ("", sampler)]
    counts = Counter((j.scene, j.method) for j in plain)
    layout = Layout.of_study(work_dir(name))
    return {**config, "results_dir": str(layout.results), "captures_dir": str(layout.captures),
            "scenes": list(dict.fromkeys(j.scene for j in plain)),
            "synthetic": {j.scene: j.synth for j in plain},
            "methods": list(dict.fromkeys(j.method for j in plain)), "samples": max(counts.values()),
            "method_params": {**config.get("method_params", {}), **{j.method: j.method_cfg for j in plain}}}


def write_workflow(jobs: list[Job], path: Path) -> None:
    """`study_workflow` of `jobs` written to `path` (YAML), named after the file."""
    from dpi.io.atomic import write_text

    write_text(path, yaml.safe_dump(study_workflow(jobs, path.stem), sort_keys=False))
    print(f"wrote {path}: snakemake --cores 2 --configfile {path}")


def latest(rows: list[dict[str, Any]], key: tuple[str, ...]) -> list[dict[str, Any]]:
    """The newest row of each `key` (the last in the file): a rerun with other settings supersedes older rows."""
    return list({tuple(row[k] for k in key): row for row in rows}.values())


def read_rows(path: Path, text: Iterable[str] = TEXT_COLUMNS) -> list[dict[str, Any]]:
    """Rows of a study CSV, numbers parsed except in the `text` columns (and the provenance columns)."""
    if not path.exists():
        return []
    keep = set(text) | set(PROVENANCE)
    with open(path, newline="") as f:
        return [{k: (v if k in keep else _number(v)) for k, v in row.items()} for row in csv.DictReader(f)]


def _number(value: str) -> float | str:
    try:
        return float(value)
    except ValueError:
        return value


def append_row(path: Path, row: dict[str, Any], columns: tuple[str, ...], settings: str) -> None:
    """Add one row (with a header when the file is new), stamped with the current commit and `settings`, the
    hash of its settings. A file whose header differs is refused, naming both (rows must not shift columns)."""
    header = (*columns, *PROVENANCE)
    path.parent.mkdir(parents=True, exist_ok=True)
    new = not path.exists() or path.stat().st_size == 0
    if not new:
        with open(path, newline="") as f:
            existing = tuple(next(csv.reader(f), ()))
        if existing != header:
            raise ValueError(f"{path}: its columns {', '.join(existing)} are not this study's "
                             f"{', '.join(header)}: write to another --out")
    with open(path, "a", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=header)
        if new:
            writer.writeheader()
        writer.writerow({**{k: row[k] for k in columns}, "commit": current_commit(), "settings_hash": settings})


def run_workflow(work: Path, config: dict[str, Any]) -> Path:
    """Write `config` (its results under `work`/results) as `work`/config.yaml and run the workflow there on 2 cores;
    the results folder."""
    work.mkdir(parents=True, exist_ok=True)
    (work / "config.yaml").write_text(yaml.safe_dump({**config, "results_dir": "results"}))
    snakemake = Path(sys.executable).with_name("snakemake")
    subprocess.run([str(snakemake), "-s", str(CHECKOUT / "Snakefile"), "--directory", str(work), "--cores", "2"],
                   check=True)
    return work / "results"


def summary_rows(results: Path, columns: Iterable[str]) -> dict[tuple[str, str], dict[str, float | str]]:
    """The workflow's evaluation summary (results/eval/summary.csv) by (scene, method): `columns` as numbers, ""
    where the summary has none."""
    with open(results / "eval" / "summary.csv", newline="") as f:
        return {(r["scene"], r["method"]): {k: float(r[k]) if r.get(k) not in (None, "") else "" for k in columns}
                for r in csv.DictReader(f)}


def write_rows(path: Path, rows: list[dict[str, Any]], settings: str) -> None:
    """Write a whole study CSV (its columns: the first row's keys), each row stamped with the current commit
    and `settings`, the hash of the settings they were made with."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=[*(k for k in rows[0] if k not in PROVENANCE), *PROVENANCE])
        writer.writeheader()
        writer.writerows({**row, "commit": current_commit(), "settings_hash": settings} for row in rows)


def mean_std_cells(rows: list[dict[str, Any]], metrics: tuple[tuple[str, str], ...]) -> list[str]:
    """`mean +- std` over the rows of each (column, format) in `metrics`, for a printed summary."""
    cells = []
    for key, fmt in metrics:
        values = np.asarray([r[key] for r in rows], dtype=float)
        cells.append(f"{values.mean():{fmt}} +- {values.std():{fmt}}")
    return cells


def job_key(job: Job) -> tuple:
    """What tells a study's samples apart: scene, method, sampler, seed and the settings' hash."""
    return job.scene, job.method, job.sampler, job.seed, job.settings_hash


def row_key(row: dict[str, Any]) -> tuple:
    """`job_key` of a CSV row."""
    return row["scene"], row["method"], row["sampler"], int(row["seed"]), row["settings_hash"]


def pool(workers: int) -> Executor | None:
    """Processes that draw samples side by side (spawned: a forked child cannot use a GPU its parent opened);
    None for 0 workers (everything in this process)."""
    if workers <= 0:
        return None
    return ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))


def run_study(jobs: list[Job], out: Path, columns: tuple[str, ...], score: Callable[[Job], dict], workers: int,
              keys: tuple[Callable, Callable] = (job_key, row_key), text: Iterable[str] = TEXT_COLUMNS,
              prepare: Callable[[Job], None] = prepare_job) -> list[dict]:
    """Prepare every scene, score the jobs whose rows `out` lacks (`score(job)` gives the row, appended as it
    comes, with the job's settings hash), and return the rows of these jobs. `keys`: a job's and a row's key,
    equal when the row is the job's, the settings hash included. `workers` 0 runs in this process."""
    of_job, of_row = keys
    scenes = list({(j.root, j.scene): j for j in jobs}.values())
    done = {of_row(r) for r in read_rows(out, text)}
    todo = [j for j in jobs if j.rerun or of_job(j) not in done]
    print(f"{len(todo)} samples to draw and score ({len(done)} rows already in {out})", flush=True)
    with pool(min(workers, len(scenes))) or nullcontext() as ex:
        list((ex.map if ex else map)(prepare, scenes))
    with pool(workers) or nullcontext() as ex:
        for job, row in zip(todo, (ex.map if ex else map)(score, todo)):
            append_row(out, row, columns, job.settings_hash)
            print("  ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()),
                  flush=True)
    wanted = {of_job(j) for j in jobs}
    return [r for r in read_rows(out, text) if of_row(r) in wanted]
