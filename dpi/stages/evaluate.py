"""Stages of rules/evaluate.smk: a sample's metrics and held-out re-renders, the run's summary tables, each
scene's env-map grid and spread maps, and the HTML report."""

from __future__ import annotations

import json
from pathlib import Path

from dpi.capture import read_capture_json
from dpi.evaluation.figures import envmap_grid, uncertainty_grid
from dpi.evaluation.realism import env_realism
from dpi.evaluation.relighting import relight_held_out
from dpi.evaluation.report import build_report
from dpi.evaluation.sample_metrics import evaluate_sample, render_held_out
from dpi.evaluation.summary import sample_rows, summarize, write_csv
from dpi.io.atomic import write_json
from dpi.io.exr import read_exr, write_exr
from dpi.io.layout import INIT_TRACE, SAMPLE_TRACE, decomposition_files, view_file
from dpi.prior.sample import load_scene_prior
from dpi.solve.spread import albedo_std_map, log_std_map, mean_log_map, roughness_std_map
from dpi.stages.inverse import load_problem
from dpi.stages.job import StageJob
from dpi.stages.seeding import seed_for


def evaluate_stage(job: StageJob) -> None:
    """Metrics of the job's sample (the init for INIT) against held-out views and ground truth, as JSON, with
    the scene's object (scene.yaml `object`, else the scene), its ground-truth env map (for the summary's set
    metrics) and the capture's exposure. The held-out views it rendered go beside it as {view}.exr, in the
    units they were compared in (the capture's radiance divided by that exposure), with its relit views (the
    truth's too) as dpi.evaluation.relighting names them, for the report. Naturalness uses the prior of the
    scene's family; realism, the panoramas of config `evaluate.reference_panoramas`, when set."""
    problem = load_problem(job.paths.capture_json, job.solve)
    sample_dir = job.sample_dir
    sample = problem.load_decomposition(sample_dir)
    traces = [sample_dir / name for name in (SAMPLE_TRACE, INIT_TRACE) if (sample_dir / name).is_file()]
    trace = json.loads(traces[0].read_text()) if traces else {}
    seconds = trace["summary"]["seconds"] if traces else None
    info = trace.get("info", {})
    sampler = info.get("sampler", "")  # which dps sampler made the sample ("" for other methods)
    reading = info.get("reading", "")  # the init's reading (the sample's: the one it started from)
    prior = load_scene_prior(problem.capture.options, job.pipeline.prior_checkpoint(job.scene))
    seed = seed_for(job.scene, job.method, job.k, "eval")
    spp = job.pipeline.evaluate_spp
    renders = render_held_out(problem, sample, spp, seed)
    relit = relight_held_out(problem, sample, spp, seed)
    metrics = {**evaluate_sample(problem, sample, spp, seed, seconds, prior, renders, relit),
               "env_realism": env_realism(sample.env.numpy(), job.config["evaluate"]["reference_panoramas"])}
    views = job.evaluation_views
    views.mkdir(parents=True, exist_ok=True)
    for name, image in {**renders, **({} if isinstance(relit, str) else relit)}.items():
        write_exr(view_file(views, name), image)
    gt_envmap = problem.capture.gt.get("envmap")
    write_json(job.evaluation, {"scene": job.scene, "method": job.method, "sampler": sampler, "reading": reading,
                                "sample": job.k,
                                "sample_dir": str(sample_dir), "object": problem.capture.options.get("object", job.scene),
                                "gt_envmap": str(gt_envmap) if gt_envmap else None, "exposure": problem.exposure,
                                "metrics": metrics})


def envmap_figure_stage(job: StageJob, rows: list[tuple[str, list[str | Path]]]) -> None:
    """The env-map grid of the job's scene: per (method, env-map files) a row of samples, below the capture's
    ground truth when it has one, scale-aligned to it."""
    envmap_grid([(method, [Path(p) for p in files]) for method, files in rows], job.paths.envmap_figure,
                read_capture_json(job.paths.capture_json).gt.get("envmap"))


def uncertainty_stage(job: StageJob, rows: list[tuple[str, list[str | Path]]]) -> None:
    """The spread maps of the job's scene: per (method, its sample folders, 2 or more) the per-texel std of the
    env maps' log luminance, of the albedo and of the roughness across the samples and the env maps' geometric
    mean, as EXRs where dpi.io.layout says, and the spread's figure."""
    scene = job.paths
    figure = []
    for method, folders in rows:
        files = [decomposition_files(folder) for folder in folders]
        envs = [read_exr(f["env"]) for f in files]
        mean, env = mean_log_map(envs), log_std_map(envs)
        albedo = albedo_std_map([read_exr(f["albedo"]) for f in files])
        roughness = roughness_std_map([read_exr(f["roughness"]) for f in files])
        paths = scene.uncertainty(method)
        write_exr(paths["env"], env)
        write_exr(paths["albedo"], albedo)
        write_exr(paths["roughness"], roughness)
        write_exr(paths["env_mean"], mean)
        figure.append((method, mean, env, albedo, roughness))
    uncertainty_grid(figure, scene.uncertainty_figure)


def summary_stage(job: StageJob, eval_jsons: list[str | Path]) -> None:
    """Aggregate per-sample metric files into the run's summary.csv (one row per scene x method, init included)
    and samples.csv."""
    records = [json.loads(Path(path).read_text()) for path in eval_jsons]
    summary = summarize(records)
    layout = job.pipeline.layout
    write_csv(layout.summary, summary)
    write_csv(layout.samples_table, sample_rows(records, summary))


def report_stage(job: StageJob) -> None:
    """The run's HTML report and its figures (dpi.evaluation.report)."""
    layout = job.pipeline.layout
    build_report(layout, layout.report_html, layout.report_figures)
