"""Resolution study (issue 32): what a finer env map buys a glossy and a rough object, and what it costs.

Scenes: a mirror-like metal torus (roughness 0.05, `glossy`) and a rough dielectric blob (0.85,
`rough`) under Mitsuba's sunsky with a low sun, rendered from a 256-row map, 12 views of 96 px on a
150 deg arc (3 held out): a mirror's views must have the pixels to show a map's detail. Per map
height (`--heights`, default 16 32 64 128), texture size and seed: the workflow's init at that size
and one `dps` sample of config.yaml's sampler, through the posterior study's jobs, scored by the
workflow's evaluation: held-out view PSNR, env PSNR (against the truth resampled to the sample's
size), relit held-out views (`relight_psnr_h`), and the sample's seconds. Then the truth at each
size: the held-out view PSNR of the true materials under the true map resampled to each height (what
the size shows at best; a fitted map can beat it at 16 rows, where resampling blurs the sun).

    .venv/bin/python benchmarks/resolution/resolution.py [--heights 16 32 64 128] [--textures 64] [--seeds 0 1 2]

Rows go to benchmarks/resolution/resolution.csv (rows already there are not rerun), then it prints
mean +- std per group, height and texture size.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dpi.io.layout import Layout
from dpi.studies.engine import (Job, job_settings, mean_std_cells, prior_checkpoints, results_csv, run_job, run_study,
                                work_dir)
from dpi.studies.scenes import RESOLUTION_SCENES as SCENES
from dpi.studies.scenes import resolution_config as size_config
from dpi.studies.scenes import resolution_root

WORK = work_dir("resolution_study")
CSV = results_csv("resolution")
COLUMNS = ("scene", "group", "env_height", "texture_size", "seed", "novel_psnr", "env_psnr", "relight_psnr_h",
           "seconds")
TEXT = ("scene", "group")
def score(job: Job) -> dict[str, Any]:
    """Draw and evaluate one sample (the engine's job); its row."""
    row = run_job(job)
    metrics = json.loads(job.layout.scene(job.scene).evaluation(job.label, job.seed).read_text())["metrics"]
    problem = job.config["problem"]
    return {**row, "env_height": problem["env_height"], "texture_size": problem["texture_size"],
            "relight_psnr_h": metrics["relight_psnr_h"]}


def job_key(job: Job) -> tuple:
    """What tells the study's samples apart: scene, map height, texture size, seed, settings hash."""
    problem = job.config["problem"]
    return job.scene, problem["env_height"], problem["texture_size"], job.seed, job.settings_hash


def row_key(row: dict[str, Any]) -> tuple:
    """`job_key` of a CSV row."""
    return row["scene"], int(row["env_height"]), int(row["texture_size"]), int(row["seed"]), row["settings_hash"]


def summary(rows: list[dict[str, Any]]) -> list[str]:
    """Mean +- std per group, height and texture size."""
    lines = [f"{'group':<7} {'height':>6} {'texture':>7} {'n':>3} {'view PSNR':>15} {'env PSNR':>15} "
             f"{'relight PSNR-H':>15} {'seconds':>13}"]
    for key in sorted({(r["group"], int(r["env_height"]), int(r["texture_size"])) for r in rows}):
        sel = [r for r in rows if (r["group"], int(r["env_height"]), int(r["texture_size"])) == key]
        cells = mean_std_cells(sel, (("novel_psnr", ".2f"), ("env_psnr", ".2f"), ("relight_psnr_h", ".2f"),
                                     ("seconds", ".1f")))
        lines.append(f"{key[0]:<7} {key[1]:>6} {key[2]:>7} {len(sel):>3} " + " ".join(f"{c:>15}" for c in cells))
    return lines


def truth_at_size(capture_json: Path, gt_dir: Path, height: int, texture: int) -> float:
    """Held-out view PSNR of the true materials under the true map resampled to `height` rows."""
    from dpi.evaluation.sample_metrics import novel_view_metrics, render_held_out
    from dpi.export.relight import prepare_envmap
    from dpi.solve.decomposition import Decomposition
    from dpi.solve.problem import SolveConfig
    from dpi.stages import load_problem

    config = size_config(height, texture)
    problem = load_problem(capture_json, SolveConfig.from_config(config, 2))
    truth = Decomposition.load(gt_dir, texture)
    env = torch.from_numpy(prepare_envmap(truth.env.numpy(), height))
    renders = render_held_out(problem, problem.to_solver_units(Decomposition(env, truth.materials)),
                              config["evaluate"]["spp"], 0)
    return novel_view_metrics(problem, renders)["novel_psnr"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--heights", nargs="*", type=int, default=[16, 32, 64, 128])
    parser.add_argument("--textures", nargs="*", type=int, default=[64])
    parser.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2])
    parser.add_argument("--jobs", type=int, default=2, help="samples drawn side by side (1 thread each)")
    parser.add_argument("--out", type=Path, default=CSV)
    parser.add_argument("--prior", nargs="*", default=[], metavar="FAMILY=CHECKPOINT",
                        help="a family's diffusion prior (config illumination_prior.checkpoints; default: shipped)")
    args = parser.parse_args()
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

    from dpi.synth.capture import SynthConfig, make_synthetic_capture

    layout = Layout.of_study(WORK)
    for scene, (_, synth) in SCENES.items():  # the shared captures first, one at a time
        if not layout.synth_marker(scene).exists():
            make_synthetic_capture(layout.capture_dir(scene), SynthConfig.from_dict(synth), threads=2, progress=False)
    jobs = []
    for height in args.heights:
        for texture in args.textures:
            config = size_config(height, texture)
            config["illumination_prior"]["checkpoints"].update(prior_checkpoints(args.prior))
            dps = job_settings(config["method_params"].get("dps", {}))
            for scene, (group, synth) in SCENES.items():
                jobs.extend(Job(resolution_root(WORK, height, texture), scene, group, synth, "dps", "", seed, dps, config)
                            for seed in args.seeds)
    rows = run_study(jobs, args.out, COLUMNS, score, args.jobs, (job_key, row_key), TEXT)
    print("\n".join(summary(rows)))
    print("truth at each size: held-out view PSNR [dB] of the true materials under the true map resampled")
    for scene, (group, _) in SCENES.items():
        truth = layout.capture_dir(scene) / "gt"
        cells = [f"{h}: {truth_at_size(Layout.of_study(resolution_root(WORK, h, t)).scene(scene).capture_json, truth, h, t):.2f}"
                 for h in args.heights for t in args.textures]
        print(f"{scene:<13} {group:<7} " + "  ".join(cells))
    from dpi.config.pipeline import Pipeline

    print(f"(dps sampler {Pipeline(size_config(16, 64)).method_settings('dps').sampler}; "
          f"{np.mean([r['seconds'] for r in rows]):.0f} s a sample on average)")


if __name__ == "__main__":
    main()
