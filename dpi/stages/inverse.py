"""Stages of rules/inverse.smk: the path-traced initialisation, posterior sample k of a method, and the sample
stop rule's plan. Each reads the scene's capture.json (completed by what preprocessing derived) and writes where
dpi.io.layout says, with the settings of the job's pipeline."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from dpi.capture import complete_capture, read_capture_json
from dpi.capture.working import working_capture
from dpi.io.atomic import write_json
from dpi.io.exr import read_exr
from dpi.io.layout import INIT, INIT_TRACE, SceneLayout
from dpi.prior.sample import load_scene_prior
from dpi.render import backend
from dpi.solve.adaptive import MIN_SAMPLES, plan_samples
from dpi.solve.decomposition import Decomposition
from dpi.solve.exposure import MIDDLE_GREY
from dpi.solve.init import path_traced_init, readings_line, sample_reading
from dpi.solve.methods import REGISTRY, SampleJob
from dpi.solve.problem import InverseProblem, SolveConfig
from dpi.stages.job import StageJob
from dpi.stages.seeding import seed_for

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


def init_stage(job: StageJob) -> None:
    """Path-traced initialisation of the job's scene into its init folder (envmap.exr, textures, log.json)."""
    problem = load_problem(job.paths.capture_json, job.solve)
    out, other = job.paths.sample_dir(INIT), job.paths.other_reading_dir()
    result = path_traced_init(problem, job.pipeline.init_settings, seed_for(job.scene, INIT), job.progress,
                              out / RESUME_FILE)
    print(f"init readings: {readings_line(result.record)}", flush=True)
    shutil.rmtree(other, ignore_errors=True)
    if result.other is not None:
        problem.save_decomposition(result.other, other, trace_name=INIT_TRACE)
    result.kept.trace.info["variant"] = backend.mitsuba().variant()
    problem.save_decomposition(result.kept, out, trace_name=INIT_TRACE)


def sample_init(job: StageJob, problem: InverseProblem) -> tuple[str, Decomposition]:
    """The reading sample job.k starts from (dpi.solve.init.sample_reading) and its decomposition."""
    readings = json.loads(job.paths.sample_files(INIT)["trace"].read_text())["info"].get("readings", {})
    reading = sample_reading(job.k, readings)
    other = reading != readings.get("kept", reading)
    return reading, problem.load_decomposition(job.paths.other_reading_dir() if other else job.paths.sample_dir(INIT))


def sample_job(job: StageJob) -> tuple[str, SampleJob]:
    """What drawing posterior sample k of the job's method needs (dpi.solve.methods.SampleJob: its settings, checked
    before anything is read, then its problem and init), and the init reading it starts from.

    A method that uses the diffusion prior loads the one of the scene's family (dpi.config.pipeline); scene.yaml's
    `radiance_scale` is in the capture's radiance."""
    cfg = job.pipeline.method_settings(job.method)
    problem = load_problem(job.paths.capture_json, job.solve)
    out = job.sample_dir
    reading, init = sample_init(job, problem)
    sample = SampleJob(problem, init, cfg, seed_for(job.scene, job.method, job.k), out, out / RESUME_FILE,
                       adaptive=job.pipeline.adaptive, progress=job.progress)
    if REGISTRY[job.method].needs_prior:
        sample.prior = load_scene_prior(problem.capture.options, job.pipeline.method_prior(job.scene, job.method))
        scale = problem.capture.options.get("radiance_scale")  # in scene radiance
        sample.radiance_scale = None if scale is None else scale / problem.exposure
    return reading, sample


def sample_stage(job: StageJob) -> None:
    """Posterior sample k of the job's method into its folder (envmap, textures, trace.json), from `sample_job`'s
    inputs. `dps` runs fewer steps on a diffuse scene (config `adaptive`); the decision and its reason are in the
    trace's info."""
    reading, sample = sample_job(job)
    result = REGISTRY[job.method].sample(sample)
    result.trace.info.update({"scene": job.scene, "k": job.k, "reading": reading})
    sample.problem.save_decomposition(result, sample.out_dir)


def sample_plan_stage(job: StageJob) -> dict:
    """The stop rule's plan.json for the job's (scene, method), from its first samples' env maps (dpi.solve.adaptive)."""
    envmaps = [job.paths.sample_files(job.method, k)["env"] for k in range(MIN_SAMPLES)]
    cfg = job.pipeline.adaptive
    plan = plan_samples([read_exr(path) for path in envmaps], job.pipeline.samples(job.method), cfg)
    write_json(job.paths.plan(job.method), {**plan, "first": [str(p) for p in envmaps], "config": vars(cfg)})
    print(f"adaptive: {plan['reason']}", flush=True)
    return plan
