"""Sun recovery: does a method's env map hold the sun where the ground truth has it? (issue 15)

Scenes: the demo object (a bumpy, textured blob, roughness 0.3, seen from all around) under
Mitsuba's sunsky with the demo's sun (35 deg elevation, azimuth 60 deg) and two more suns at other
elevations and azimuths, at the posterior study's image sizes. For `dps` (the sampler config.yaml
picks) and `none`, per seed, through the posterior study's jobs (benchmarks/posterior/posterior.py):
- top_energy_share: the share of the map's energy (luminance x solid angle) in its brightest 0.5 %
  of texels, and the same for the ground truth (a sun carries about half of it);
- sun_angle_deg: the angle between the direction of the map's brightest texel and the true sun;
- novel_psnr: held-out view PSNR, as in the posterior study.

A reference row per scene and seed, `true_light`, is not a method: the ground-truth map (area-
resampled to the problem's size) is held fixed (no gain) while dps's refinement fits the materials
from where every method starts (dpi.solve.init.starting_materials). Its view PSNR is what a perfect
light recovery would give with this material fit.

    .venv/bin/python notebook/scripts/sun_study.py [--seeds 0 1 2 3 4 5] [--jobs 2]

Rows go to notebook/results/sun_study.csv (rows already there are not rerun), then it prints
mean +- std per scene and method.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from dpi.capture import load_capture
from dpi.io.exr import read_exr
from dpi.io.images import luminance
from dpi.light.envmap import texel_directions, top_energy_share
from dpi.solve.dps import DPSConfig
from dpi.studies.engine import (Job, dps_variants, job_settings, mean_std_cells, method_jobs, run_job, run_study,
                                workflow_config)
from dpi.studies.scenes import SIZE
from dpi.worlds.skies import sun_direction

ROOT = Path(__file__).resolve().parents[2]
WORK = ROOT / "results" / "benchmarks" / "sun_study"
CSV = Path(__file__).resolve().parents[1] / "results" / "sun_study.csv"
COLUMNS = ("scene", "method", "sampler", "seed", "top_energy_share", "gt_top_energy_share", "sun_angle_deg", "novel_psnr")
DEMO = {**SIZE, "shape": "blob", "seed": 0, "roughness": 0.3, "environment": "sunsky", "prior": "outdoor"}
SUNS = {"demo_sun": (35.0, 60.0), "low_sun": (8.0, 250.0), "high_sun": (65.0, 150.0)}
SCENES = {name: ("sun", {**DEMO, "sun_elevation_deg": elevation, "sun_azimuth_deg": azimuth})
          for name, (elevation, azimuth) in SUNS.items()}
METHODS = ("dps", "none")
TRUE_LIGHT = "true_light"


def brightest_direction(env: np.ndarray) -> np.ndarray:
    """World direction of the map's brightest texel (by luminance)."""
    row, col = np.unravel_index(np.argmax(luminance(env)), env.shape[:2])
    return texel_directions(env.shape[0])[row, col]


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two unit vectors in degrees."""
    return math.degrees(math.acos(float(np.clip(np.dot(a, b), -1.0, 1.0))))


def true_light_sample(job: Job) -> None:
    """The `true_light` reference's sample folder (module notes), unless it is there."""
    import torch

    from dpi.light.envmap import read_envmap
    from dpi.prior.data import resize_map
    from dpi.solve.decomposition import Decomposition
    from dpi.solve.init import starting_materials
    from dpi.solve.optimize import fit
    from dpi.solve.problem import SolveConfig
    from dpi.solve.trace import Trace
    from dpi.stages import load_problem

    files = job.layout.scene(job.scene)
    if files.sample_files(job.label, job.seed)["trace"].exists():
        return
    problem = load_problem(files.capture_json, SolveConfig.from_config(job.config, threads=1))
    gt = torch.from_numpy(read_envmap(problem.capture.gt["envmap"])).float().permute(2, 0, 1)
    env = resize_map(gt, problem.settings.env_height).permute(1, 2, 0)
    init = problem.load_decomposition(files.sample_dir("init"))
    cfg = DPSConfig.from_dict(job.method_cfg)
    trace = Trace()  # dps's refinement; the true map stays as it is
    log_env, materials = fit(problem, (env / problem.exposure).log(), starting_materials(init),
                             cfg.refine.optimize(cfg), job.seed, trace, progress=False, free_env=False)
    problem.save_decomposition(Decomposition(log_env.exp(), materials, trace), job.sample_dir)


def score(job: Job) -> dict[str, Any]:
    """Draw and evaluate one sample (the posterior study's job; the true-light reference's folder is
    made here), then measure its sun."""
    if job.method == TRUE_LIGHT:
        true_light_sample(job)
    row = run_job(job)
    env = read_exr(job.layout.scene(job.scene).sample_files(job.label, job.seed)["env"])
    gt = read_exr(load_capture(job.layout.capture_dir(job.scene)).gt["envmap"])
    sun = sun_direction(*SUNS[job.scene])
    return {"scene": job.scene, "method": job.method, "sampler": job.sampler, "seed": job.seed,
            "top_energy_share": top_energy_share(env), "gt_top_energy_share": top_energy_share(gt),
            "sun_angle_deg": angle_deg(brightest_direction(env), sun), "novel_psnr": row["novel_psnr"]}


def summary(rows: list[dict[str, Any]]) -> list[str]:
    """Mean +- std per scene and method."""
    lines = [f"{'scene':<10} {'method':<16} {'n':>2} {'top 0.5 % share':>16} {'gt share':>9} {'sun angle':>15} "
             f"{'view PSNR':>14}"]
    for scene in SCENES:
        for method in (*METHODS, TRUE_LIGHT):
            for sampler in sorted({r["sampler"] for r in rows if r["method"] == method}):
                sel = [r for r in rows if r["scene"] == scene and r["method"] == method and r["sampler"] == sampler]
                if sel:
                    lines.append(summary_line(scene, f"{method} {sampler}".strip(), sel))
    return lines


def summary_line(scene: str, label: str, sel: list[dict[str, Any]]) -> str:
    """One scene and method's mean +- std cells."""
    cells = mean_std_cells(sel, (("top_energy_share", ".3f"), ("sun_angle_deg", ".1f"), ("novel_psnr", ".2f")))
    return (f"{scene:<10} {label:<16} {len(sel):>2} {cells[0]:>16} {sel[0]['gt_top_energy_share']:>9.3f} "
            f"{cells[1]:>15} {cells[2]:>14}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", nargs="*", default=list(SCENES), choices=list(SCENES))
    parser.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2])
    parser.add_argument("--methods", nargs="*", default=[*METHODS, TRUE_LIGHT], choices=[*METHODS, TRUE_LIGHT])
    parser.add_argument("--dps", nargs="*", default=[], metavar="NAME:key=value,...",
                        help="dps variants drawn instead of config.yaml's sampler (dev studies)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", type=Path, default=CSV)
    args = parser.parse_args()
    config = workflow_config(env_height=16)
    dps = job_settings(config["method_params"].get("dps", {}))
    samplers = [spec.partition(":")[0] for spec in args.dps] or [DPSConfig.from_dict(dps).sampler]
    scenes = {name: SCENES[name] for name in args.scenes}
    jobs = method_jobs(WORK, scenes, args.methods, args.seeds, config, dps_variants(config, args.dps), samplers)
    jobs = [replace(j, method_cfg=dps, sampler="") if j.method == TRUE_LIGHT else j for j in jobs]
    print("\n".join(summary(run_study(jobs, args.out, COLUMNS, score, args.jobs))))


if __name__ == "__main__":
    main()
