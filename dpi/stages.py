"""Pipeline stages as functions of paths and plain settings: what each Snakemake rule (and the
`dpi` command) runs. Each reads its inputs, calls the library, and writes its outputs atomically.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from dpi import backend
from dpi.adaptive import AdaptiveConfig, plan_steps
from dpi.atomic import write_json
from dpi.capture import load_capture, read_capture_json, write_capture_json
from dpi.exposure import MIDDLE_GREY
from dpi.evaluate import evaluate_sample, sample_rows, summarize, write_csv
from dpi.render import RenderSettings
from dpi.seeding import seed_for
from dpi.solve.classic import classic_sample
from dpi.prior.sample import load_scene_prior, write_grid
from dpi.solve.dip import dip_sample
from dpi.solve.dps import dps_sample
from dpi.solve.sds import sds_sample
from dpi.solve.init import path_traced_init
from dpi.solve.methods import DIFFUSION_METHODS, method_config
from dpi.solve.optimize import OptimizeConfig
from dpi.solve.problem import InverseProblem, ProblemSettings

RESUME_FILE = ".resume.pt"
"""a long job's resume state in its output folder: no Snakemake output, so it outlives the deletion of a
killed job's outputs and the rerun continues from it (dpi.solve.checkpoint)"""


@dataclass
class SolveSettings:
    """Renderer and unknowns' resolution shared by init, methods and evaluation."""

    render: RenderSettings = field(default_factory=RenderSettings)
    problem: ProblemSettings = field(default_factory=ProblemSettings)

    @classmethod
    def from_config(cls, config: dict[str, Any], threads: int | None = None) -> "SolveSettings":
        """Settings from the `render` and `problem` sections of config.yaml."""
        render = RenderSettings(**{**config.get("render", {}), "threads": threads})
        return cls(render, ProblemSettings(**config.get("problem", {})))


def capture_stage(capture_dir: str | Path, out_json: str | Path) -> None:
    """Validate a capture folder once and write its normalised description (capture.json)."""
    write_capture_json(load_capture(capture_dir), out_json)


def load_problem(capture_json: str | Path, settings: SolveSettings, derived: dict | None = None) -> InverseProblem:
    """The inverse problem of a validated capture, completed by the cameras, masks and UV mesh that
    preprocessing derived where the capture lacks them (default: next to capture.json; `derived`
    overrides with keys cameras, masks, mesh)."""
    from dpi.preprocess.stages import complete_capture

    capture = complete_capture(read_capture_json(capture_json), Path(capture_json).parent, derived)
    problem = InverseProblem(capture, settings.problem, settings.render)
    print(f"exposure: images divided by {problem.exposure:.6g} (foreground median at {MIDDLE_GREY})", flush=True)
    return problem


def init_stage(capture_json: str | Path, out_dir: str | Path, scene: str, init_cfg: dict[str, Any],
               settings: SolveSettings, progress: bool = True) -> None:
    """Path-traced initialisation of one scene into out_dir (envmap.exr, textures, log.json)."""
    problem = load_problem(capture_json, settings)
    result = path_traced_init(problem, OptimizeConfig.from_dict(init_cfg), seed_for(scene, "init"), progress,
                              Path(out_dir) / RESUME_FILE)
    result.trace.info["variant"] = backend.mitsuba().variant()
    problem.save_decomposition(result, out_dir, trace_name="log.json")


def sample_stage(capture_json: str | Path, init_dir: str | Path, out_dir: str | Path, scene: str, method: str,
                 k: int, method_cfg: dict[str, Any], settings: SolveSettings, prior_checkpoint: str | Path | None = None,
                 adaptive: AdaptiveConfig | None = None, progress: bool = True) -> None:
    """Posterior sample k of a method for one scene, into out_dir (envmap, textures, trace.json).

    `dps` and `sds` use the diffusion prior in `prior_checkpoint` (default: the shipped model of the scene's
    family, from scene.yaml's `prior`, else outdoor). `dps` runs fewer steps on a diffuse scene (`adaptive`,
    default AdaptiveConfig()); the decision and its reason are in the trace's info."""
    cfg = method_config(method, method_cfg)
    problem = load_problem(capture_json, settings)
    init = problem.load_decomposition(init_dir)
    seed = seed_for(scene, method, k)
    resume = Path(out_dir) / RESUME_FILE
    if method in DIFFUSION_METHODS:
        prior = load_scene_prior(problem.capture.options, prior_checkpoint)
        scale = cfg.radiance_scale or problem.capture.options.get("radiance_scale")  # in scene radiance
        cfg.radiance_scale = None if scale is None else scale / problem.exposure
        if method == "dps":
            requested = cfg.steps
            cfg.steps, reason = plan_steps(init.materials, cfg.steps, adaptive or AdaptiveConfig())
            print(f"adaptive: {reason}", flush=True)
            dps = dps_sample(problem, prior, init, cfg, seed, progress, resume)
            result = dps.decomposition
            result.trace.info["adaptive"] = {"steps": cfg.steps, "requested_steps": requested, "reason": reason}
            write_grid(Path(out_dir) / "x0_strip.png", torch.stack(dps.snapshots), columns=len(dps.snapshots))
        else:
            result = sds_sample(problem, prior, init, cfg, seed, progress)
    elif method == "dip":
        result = dip_sample(problem, init, cfg, seed, progress, resume)
    else:
        result = classic_sample(problem, method, init, cfg, seed, progress, resume)
    result.trace.info.update({"scene": scene, "k": k})
    problem.save_decomposition(result, out_dir)


def evaluate_stage(capture_json: str | Path, sample_dir: str | Path, out_json: str | Path, scene: str,
                   method: str, k: int, spp: int, settings: SolveSettings,
                   prior_checkpoint: str | Path | None = None) -> None:
    """Metrics of one sample against held-out views and ground truth, as JSON, with the scene's object
    (scene.yaml `object`, else the scene) and ground-truth env map for the summary's set metrics.
    Naturalness uses the prior in `prior_checkpoint` (default: the shipped model of the scene's family)."""
    problem = load_problem(capture_json, settings)
    sample = problem.load_decomposition(sample_dir)
    traces = [Path(sample_dir) / name for name in ("trace.json", "log.json") if (Path(sample_dir) / name).is_file()]
    seconds = json.loads(traces[0].read_text())["summary"]["seconds"] if traces else None
    prior = load_scene_prior(problem.capture.options, prior_checkpoint)
    metrics = evaluate_sample(problem, sample, spp, seed_for(scene, method, k, "eval"), seconds, prior)
    gt_envmap = problem.capture.gt.get("envmap")
    write_json(out_json, {"scene": scene, "method": method, "sample": k, "sample_dir": str(sample_dir),
                          "object": problem.capture.options.get("object", scene),
                          "gt_envmap": str(gt_envmap) if gt_envmap else None, "metrics": metrics})


def summary_stage(eval_jsons: list[str | Path], out_csv: str | Path, samples_csv: str | Path | None = None) -> None:
    """Aggregate per-sample metric files into summary.csv (one row per scene x method, init included)."""
    records = [json.loads(Path(path).read_text()) for path in eval_jsons]
    summary = summarize(records)
    write_csv(out_csv, summary)
    if samples_csv is not None:
        write_csv(samples_csv, sample_rows(records, summary))
