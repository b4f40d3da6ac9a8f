"""The inverse and evaluation stages as functions of paths and typed settings: what each Snakemake rule (and
the `dpi` command) runs after the capture. Each reads its inputs, calls the library, and writes its outputs
atomically where dpi.layout says. The preprocessing group's stages are in dpi.preprocess.stages (capture_stage is
importable from here too), the settings of a workflow config come from dpi.pipeline.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from dpi import backend
from dpi.adaptive import AdaptiveConfig
from dpi.capture import complete_capture, read_capture_json
from dpi.evaluation.figures import envmap_grid, uncertainty_grid
from dpi.evaluation.realism import env_realism
from dpi.evaluation.relighting import relight_held_out
from dpi.evaluation.sample_metrics import evaluate_sample, render_held_out
from dpi.evaluation.summary import sample_rows, summarize, write_csv
from dpi.exposure import MIDDLE_GREY
from dpi.io.atomic import write_json
from dpi.io.exr import read_exr, write_exr
from dpi.layout import INIT, INIT_TRACE, SAMPLE_TRACE, SceneLayout, decomposition_files, view_file
from dpi.preprocess.stages import capture_stage  # noqa: F401  (the first stage of every scene)
from dpi.prior.sample import load_scene_prior
from dpi.seeding import seed_for
from dpi.solve.init import InitConfig, path_traced_init
from dpi.solve.methods import REGISTRY, SampleJob, method_config
from dpi.solve.problem import InverseProblem, SolveConfig
from dpi.spread import albedo_std_map, log_std_map, mean_log_map
from dpi.working import working_capture

RESUME_FILE = ".resume.pt"
"""a long job's resume state in its output folder: no Snakemake output, so it outlives the deletion of a
killed job's outputs and the rerun continues from it (dpi.solve.checkpoint)"""


def load_problem(capture_json: str | Path, settings: SolveConfig) -> InverseProblem:
    """The inverse problem of a validated capture, completed by the cameras, masks and UV mesh that
    preprocessing derived where the capture lacks them (in the scene's results folder, next to capture.json),
    at the working resolution (`problem.resolution`)."""
    scene = SceneLayout(Path(capture_json).parent)
    full = complete_capture(read_capture_json(capture_json), scene)
    capture = working_capture(full, settings.problem.resolution, scene.working_dir)
    if capture is not full:
        print(f"working resolution: {full.image_size[0]}x{full.image_size[1]} images fitted at "
              f"{capture.image_size[0]}x{capture.image_size[1]} ({scene.working_dir})", flush=True)
    problem = InverseProblem(capture, settings.problem, settings.render)
    print(f"exposure: images divided by {problem.exposure:.6g} (foreground median at {MIDDLE_GREY})", flush=True)
    return problem


def init_stage(capture_json: str | Path, out_dir: str | Path, scene: str, init_cfg: dict[str, Any],
               settings: SolveConfig, progress: bool = True) -> None:
    """Path-traced initialisation of one scene into out_dir (envmap.exr, textures, log.json)."""
    problem = load_problem(capture_json, settings)
    result = path_traced_init(problem, InitConfig.from_dict(init_cfg), seed_for(scene, INIT), progress,
                              Path(out_dir) / RESUME_FILE)
    result.trace.info["variant"] = backend.mitsuba().variant()
    problem.save_decomposition(result, out_dir, trace_name=INIT_TRACE)


def sample_stage(capture_json: str | Path, init_dir: str | Path, out_dir: str | Path, scene: str, method: str,
                 k: int, method_cfg: dict[str, Any], settings: SolveConfig, prior_checkpoint: str | Path | None = None,
                 adaptive: AdaptiveConfig | None = None, progress: bool = True) -> None:
    """Posterior sample k of a method for one scene, into out_dir (envmap, textures, trace.json).

    Methods that use the diffusion prior (dpi.solve.methods) load the one in `prior_checkpoint` (default: the
    shipped model of the scene's family, from scene.yaml's `prior`); scene.yaml's `radiance_scale` is in the
    capture's radiance. `dps` runs fewer steps on a diffuse scene (`adaptive`, default
    AdaptiveConfig()); the decision and its reason are in the trace's info."""
    cfg = method_config(method, method_cfg)
    entry = REGISTRY[method]
    problem = load_problem(capture_json, settings)
    job = SampleJob(problem, problem.load_decomposition(init_dir), cfg, seed_for(scene, method, k), Path(out_dir),
                    Path(out_dir) / RESUME_FILE, adaptive=adaptive, progress=progress)
    if entry.needs_prior:
        job.prior = load_scene_prior(problem.capture.options, prior_checkpoint)
        scale = problem.capture.options.get("radiance_scale")  # in scene radiance
        job.radiance_scale = None if scale is None else scale / problem.exposure
    result = entry.sample(job)
    result.trace.info.update({"scene": scene, "k": k})
    problem.save_decomposition(result, out_dir)


def evaluate_stage(capture_json: str | Path, sample_dir: str | Path, out_json: str | Path, scene: str,
                   method: str, k: int, spp: int, settings: SolveConfig,
                   prior_checkpoint: str | Path | None = None, views_dir: str | Path | None = None,
                   references: str | Path | None = None) -> None:
    """Metrics of one sample against held-out views and ground truth, as JSON, with the scene's object
    (scene.yaml `object`, else the scene), its ground-truth env map (for the summary's set metrics) and the
    capture's exposure. With `views_dir`, the held-out views it rendered go there as {view}.exr, in the units
    they were compared in (the capture's radiance divided by that exposure), and its relit views (the truth's
    too) as dpi.evaluation.relighting names them, for the report.
    Naturalness uses the prior in `prior_checkpoint` (default: the shipped model of the scene's family); realism,
    the panoramas of the folder `references` (config evaluate.reference_panoramas), when given."""
    problem = load_problem(capture_json, settings)
    sample = problem.load_decomposition(sample_dir)
    traces = [Path(sample_dir) / name for name in (SAMPLE_TRACE, INIT_TRACE) if (Path(sample_dir) / name).is_file()]
    trace = json.loads(traces[0].read_text()) if traces else {}
    seconds = trace["summary"]["seconds"] if traces else None
    sampler = trace.get("info", {}).get("sampler", "")  # which dps sampler made the sample ("" for other methods)
    prior = load_scene_prior(problem.capture.options, prior_checkpoint)
    seed = seed_for(scene, method, k, "eval")
    renders = render_held_out(problem, sample, spp, seed)
    relit = relight_held_out(problem, sample, spp, seed)
    metrics = {**evaluate_sample(problem, sample, spp, seed, seconds, prior, renders, relit),
               "env_realism": env_realism(sample.env.numpy(), references)}
    if views_dir is not None:
        Path(views_dir).mkdir(parents=True, exist_ok=True)
        for name, image in {**renders, **({} if isinstance(relit, str) else relit)}.items():
            write_exr(view_file(views_dir, name), image)
    gt_envmap = problem.capture.gt.get("envmap")
    write_json(out_json, {"scene": scene, "method": method, "sampler": sampler, "sample": k, "sample_dir": str(sample_dir),
                          "object": problem.capture.options.get("object", scene),
                          "gt_envmap": str(gt_envmap) if gt_envmap else None, "exposure": problem.exposure,
                          "metrics": metrics})


def envmap_figure_stage(capture_json: str | Path, rows: list[tuple[str, list[str | Path]]], out_png: str | Path) -> None:
    """The env-map grid of one scene: per (method, env-map files) a row of samples, below the capture's ground
    truth when it has one, scale-aligned to it."""
    envmap_grid([(method, [Path(p) for p in files]) for method, files in rows], out_png,
                read_capture_json(capture_json).gt.get("envmap"))


def uncertainty_stage(scene_dir: str | Path, rows: list[tuple[str, list[str | Path]]], out_png: str | Path) -> None:
    """The spread maps of one scene: per (method, its sample folders, 2 or more) the per-texel std of the env
    maps' log luminance and of the albedo across the samples and the env maps' geometric mean, as EXRs where
    dpi.layout says, and the spread's figure."""
    scene = SceneLayout(Path(scene_dir))
    figure = []
    for method, folders in rows:
        files = [decomposition_files(folder) for folder in folders]
        envs = [read_exr(f["env"]) for f in files]
        mean, env = mean_log_map(envs), log_std_map(envs)
        albedo = albedo_std_map([read_exr(f["albedo"]) for f in files])
        write_exr(scene.uncertainty(method)["env"], env)
        write_exr(scene.uncertainty(method)["albedo"], albedo)
        write_exr(scene.uncertainty(method)["env_mean"], mean)
        figure.append((method, mean, env, albedo))
    uncertainty_grid(figure, out_png)


def summary_stage(eval_jsons: list[str | Path], out_csv: str | Path, samples_csv: str | Path | None = None) -> None:
    """Aggregate per-sample metric files into summary.csv (one row per scene x method, init included)."""
    records = [json.loads(Path(path).read_text()) for path in eval_jsons]
    summary = summarize(records)
    write_csv(out_csv, summary)
    if samples_csv is not None:
        write_csv(samples_csv, sample_rows(records, summary))
