"""Calibration study: does the spread of a method's samples follow what the views leave open (issue 31)?

Scenes: two objects (blob, bumpy torus) x three lights the priors never saw (an outdoor map with a
sun, an indoor room, an outdoor map clipped like an 8-bit panorama) x two materials (mirror-like
metal, roughness 0.05; rough dielectric, roughness 0.85), at the posterior study's sizes, views on a
150 deg arc. Each repeat is its own capture (render noise) and initialisation; every method then
draws `--samples` samples from the repeat's own seed stream through the workflow's stage functions,
and the workflow's evaluation scores them.

Per (scene, method, sampler, repeat), one row of benchmarks/calibration/calibration.csv: the
samples' mean env PSNR / SSIM, albedo MSE, novel-view PSNR and seconds, their env sigma2_sample,
and their calibration: the mean squared scale-aligned log-radiance distance of the samples to the
truth over the mean pairwise distance between them (dpi.solve.spread.calibration; ~1 when the truth looks
like one more sample, >> 1 when the samples agree on a wrong guess). Then it prints mean +- std per
material, method and sampler, and the metal / rough ratio of sigma2_sample per object and repeat.

    .venv/bin/python benchmarks/calibration/calibration.py [--methods ...] [--samplers ...] [--dps NAME:key=value,...]
        [--repeats 3] [--samples 4]

Samples already drawn are reused; rows already in the CSV with the same settings hash are kept and not
recomputed.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from dpi.studies.engine import (TEXT_COLUMNS, Job, append_row, dps_variants, job_settings, mean_std_cells, pool,
                                prepare_job, read_rows, results_csv, run_job, work_dir, workflow_config)
from dpi.studies.scenes import calibration_scenes as scenes
from dpi.studies.scenes import repeat_scene, repeat_synth

WORK = work_dir("calibration_study")
REPEATS = 3
"""repeats per scene (each its own capture noise, init and seed stream)"""
CSV = results_csv("calibration")
COLUMNS = ("scene", "object", "light", "roughness", "metallic", "method", "sampler", "repeat", "samples", "env_psnr",
           "env_ssim", "albedo_mse", "novel_psnr", "env_sigma2_sample", "calibration", "seconds")
METHODS = ("init", "none", "sds", "dip", "gan", "reni", "dps")


def sample_jobs(args: argparse.Namespace, config: dict) -> dict[tuple[str, str, str, int], list[Job]]:
    """(scene, method, sampler, repeat) -> the jobs of its samples (the init: one job)."""
    variants = dps_variants(config, args.dps)
    groups: dict[tuple[str, str, str, int], list[Job]] = {}
    for scene, synth in scenes().items():
        if args.scenes and scene not in args.scenes:
            continue
        for repeat in range(args.repeats):
            name, own = repeat_scene(scene, repeat), repeat_synth(synth, repeat)
            for method in args.methods:
                labels = {s: variants[s] for s in args.samplers} if method == "dps" else \
                    {"": config["method_params"].get(method, {})}
                for sampler, cfg in labels.items():
                    cfg = job_settings(cfg)
                    seeds = [0] if method == "init" else [1000 * repeat + k for k in range(args.samples)]
                    groups[(scene, method, sampler, repeat)] = [
                        Job(WORK, name, "calibration", own, method, sampler, s, cfg, config) for s in seeds]
    return groups


def group_row(key: tuple[str, str, str, int], rows: list[dict[str, Any]], jobs: list[Job]) -> dict[str, Any]:
    """The study's row of one group of samples: means of the sample metrics, spread and calibration."""
    from dpi.capture import load_capture
    from dpi.io.exr import read_exr
    from dpi.solve.spread import calibration, normalized_env, sample_variance

    scene, method, sampler, repeat = key
    synth = jobs[0].synth
    envs = [read_exr(job.layout.scene(job.scene).sample_files(job.label, job.seed)["env"]) for job in jobs]
    truth = read_exr(load_capture(jobs[0].layout.capture_dir(jobs[0].scene)).gt["envmap"])
    means = {k: float(np.mean([r[k] for r in rows])) for k in ("env_psnr", "env_ssim", "albedo_mse", "novel_psnr",
                                                                "seconds")}
    return {"scene": scene, "object": synth["object"], "light": scene.split("_")[1], "roughness": synth["roughness"],
            "metallic": synth["metallic"], "method": method, "sampler": sampler, "repeat": repeat,
            "samples": len(jobs), **means, "env_sigma2_sample": sample_variance([normalized_env(e) for e in envs]),
            "calibration": calibration(envs, truth) if len(envs) > 1 else float("nan")}


def summary(rows: list[dict[str, Any]]) -> list[str]:
    """Mean +- std per material, method and sampler; then the metal / rough sigma2_sample ratios."""
    lines = [f"{'material':<8} {'method':<6} {'sampler':<9} {'n':>3} {'env PSNR':>13} {'albedo MSE':>17} "
             f"{'view PSNR':>13} {'sigma2':>17} {'calibration':>13} {'seconds':>11}"]
    keys = sorted({("metal" if r["metallic"] else "rough", r["method"], r["sampler"]) for r in rows},
                  key=lambda k: (k[0], METHODS.index(k[1]) if k[1] in METHODS else 99, k[2]))
    for material, method, sampler in keys:
        sel = [r for r in rows if ("metal" if r["metallic"] else "rough", r["method"], r["sampler"])
               == (material, method, sampler)]
        cells = mean_std_cells(sel, (("env_psnr", ".2f"), ("albedo_mse", ".4f"), ("novel_psnr", ".2f"),
                                     ("env_sigma2_sample", ".5f"), ("calibration", ".2f"), ("seconds", ".1f")))
        lines.append(f"{material:<8} {method:<6} {sampler:<9} {len(sel):>3} " + " ".join(
            f"{c:>{w}}" for c, w in zip(cells, (13, 17, 13, 17, 13, 11))))
    lines.append("metal / rough env sigma2_sample, per object, light and repeat:")
    for method, sampler in sorted({(r["method"], r["sampler"]) for r in rows if r["method"] != "init"}):
        ratios = []
        for r in rows:
            if (r["method"], r["sampler"]) == (method, sampler) and r["metallic"]:
                rough = [o for o in rows if (o["method"], o["sampler"], o["object"], o["light"], o["repeat"])
                         == (method, sampler, r["object"], r["light"], r["repeat"]) and not o["metallic"]]
                if rough and rough[0]["env_sigma2_sample"] > 0:
                    ratios.append(r["env_sigma2_sample"] / rough[0]["env_sigma2_sample"])
        if ratios:
            lines.append(f"  {method} {sampler}: " + " ".join(f"{x:.2f}" for x in ratios)
                         + f"  (max {max(ratios):.2f})")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", nargs="*", default=None, choices=list(scenes()))
    parser.add_argument("--methods", nargs="*", default=list(METHODS), choices=list(METHODS))
    parser.add_argument("--samplers", nargs="*", default=["proximal"], help="dps samplers (or --dps labels)")
    parser.add_argument("--dps", nargs="*", default=[], metavar="NAME:key=value,...", help="extra dps variants")
    parser.add_argument("--repeats", type=int, default=REPEATS)
    parser.add_argument("--samples", type=int, default=4)
    parser.add_argument("--jobs", type=int, default=2, help="samples drawn side by side (1 thread each)")
    parser.add_argument("--out", type=Path, default=CSV)
    args = parser.parse_args()

    config = workflow_config(env_height=16)
    groups = sample_jobs(args, config)
    text = TEXT_COLUMNS + ("object", "light")
    keyed = {(*key, jobs[0].settings_hash): jobs for key, jobs in groups.items()}

    def row_key(r: dict) -> tuple:
        return r["scene"], r["method"], r["sampler"], int(r["repeat"]), r["settings_hash"]

    done = {row_key(r) for r in read_rows(args.out, text)}
    todo = {k: v for k, v in keyed.items() if k not in done}
    inits = list({j.scene: j for jobs in todo.values() for j in jobs}.values())
    print(f"{len(todo)} groups to draw ({sum(len(v) for v in todo.values())} samples); {len(done)} rows already "
          f"in {args.out}", flush=True)
    with pool(max(args.jobs, 1)) as workers:
        list(workers.map(prepare_job, inits))
        for key, jobs in todo.items():
            row = group_row(key[:4], list(workers.map(run_job, jobs)), jobs)
            append_row(args.out, row, COLUMNS, key[4])
            print("  ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()), flush=True)
    rows = [r for r in read_rows(args.out, text) if row_key(r) in keyed]
    print("\n".join(summary(rows)))


if __name__ == "__main__":
    main()
