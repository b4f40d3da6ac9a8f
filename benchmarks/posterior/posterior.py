"""Posterior-sampling study: every method and every dps sampler over scenes and seeds (issue 16).

Scenes are synthetic captures with ground truth, built from illuminations the priors never saw
(procedural maps from the evaluation seed stream, Mitsuba's sunsky). The `ambiguous` group is
where the paper shows a prior's worth: rough dielectric objects seen from few views on a limited
arc, under a sun map, an indoor room and a map clipped to the paper's tone-curve range (like its
8-bit test panoramas). The `glossy` group is a shiny metal object seen from all around, where a
free fit already recovers the light and a prior can only tie. With `--panoramas DIR` the `real` group
joins: ambiguous objects under the manifest's held-out real panoramas (dpi.studies.scenes.REAL_LIGHT_SCENES).
`--dev` draws the design scenes instead (DEV_SCENES: where a sampler's design is chosen) and `--held-out` the
held-out light scenes (HELD_OUT_LIGHT_SCENES: where a chosen design is judged), each in its own folder.
Each scene gets one initialisation; each method then draws one sample per seed through the workflow's own
stage functions (dpi.stages) with config.yaml's settings (preset applied), and the workflow's
evaluation scores it.

    .venv/bin/python benchmarks/posterior/posterior.py [--panoramas DIR] [--scenes ...] [--methods ...] [--seeds 0 1 2]

Rows go to benchmarks/posterior/posterior.csv (one per scene, method, sampler, seed and settings
hash; rows already there with the same settings are kept and not rerun, so an interrupted study
continues, and other settings add rows), then it prints mean +- std per group, method and sampler.
`--dps NAME:key=value,...` adds a dps variant (dev sweeps: `--out notebook/results/dev/NAME.csv`).
`--workflow FILE.yaml` writes the same scenes and methods as a workflow config instead, for the workflow's
report (the paper's Tables 2-3 as a workflow).
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path
from typing import Any

from dpi.studies.engine import (SAMPLE_COLUMNS, dps_variants, mean_std_cells, method_jobs, prior_checkpoints,
                                results_csv, run_job, run_study, work_dir, workflow_config, write_workflow)
from dpi.studies.scenes import (DEV_SCENES, HELD_OUT_LIGHT_SCENES, POSTERIOR_SCENES, REAL_LIGHT_SCENES,
                                real_light_scenes)

WORK = work_dir("posterior_study")
DEV_WORK = work_dir("light_dev")
HELD_OUT_WORK = work_dir("light_held_out")
CSV = results_csv("posterior")
METHODS = ("init", "none", "smoothness", "sds", "dip", "gan", "reni", "dps")


def summary(rows: list[dict[str, Any]]) -> list[str]:
    """Mean +- std per group, method and sampler over scenes and seeds (a cell only where every row has it)."""
    shown = (("novel_psnr", ".2f"), ("env_psnr", ".2f"), ("env_ssim", ".3f"), ("albedo_mse", ".4f"),
             ("relight_psnr_h", ".2f"), ("relight_psnr_l", ".2f"), ("train_fit_over_truth", ".2f"), ("seconds", ".1f"))
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
    parser.add_argument("--scenes", nargs="*", default=None,
                        choices=[*POSTERIOR_SCENES, *REAL_LIGHT_SCENES, *DEV_SCENES, *HELD_OUT_LIGHT_SCENES],
                        help="default: every scene (the real-light ones with --panoramas)")
    parser.add_argument("--dev", action="store_true",
                        help="the design scenes instead (dpi.studies.scenes.DEV_SCENES; needs --panoramas), in their "
                             "own folder: for choosing a design apart from the study's scenes")
    parser.add_argument("--held-out", action="store_true",
                        help="the held-out light scenes instead (dpi.studies.scenes.HELD_OUT_LIGHT_SCENES; needs "
                             "--panoramas), in their own folder: for judging a chosen design on scenes it was not "
                             "chosen on")
    parser.add_argument("--panoramas", type=Path, default=None,
                        help="folder holding the manifest's held-out panoramas: adds the real-light scenes")
    parser.add_argument("--methods", nargs="*", default=list(METHODS), choices=list(METHODS))
    parser.add_argument("--samplers", nargs="*", default=None, help="dps sampler labels to run (default: all)")
    parser.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2])
    parser.add_argument("--dps", nargs="*", default=[], metavar="NAME:key=value,...", help="extra dps variants")
    parser.add_argument("--jobs", type=int, default=2, help="samples drawn side by side (1 thread each)")
    parser.add_argument("--out", type=Path, default=CSV, help="study CSV (rows already there are not rerun)")
    parser.add_argument("--prior", nargs="*", default=[], metavar="FAMILY=CHECKPOINT",
                        help="a family's diffusion prior (config illumination_prior.checkpoints; default: shipped); "
                             "dps rows are labelled SAMPLER@SIZE after the checkpoints' names (outdoor_64x128.pt: "
                             "64x128)")
    parser.add_argument("--rerun", action="store_true", help="redo rows already in the CSV (their samples too)")
    parser.add_argument("--work", type=Path, default=None,
                        help="study folder: captures, inits and samples (default: results/benchmarks/posterior_study, "
                             "with --dev results/benchmarks/light_dev; another folder: other inits, dev studies)")
    parser.add_argument("--workflow", type=Path, default=None, metavar="FILE.yaml",
                        help="write the study as a workflow config instead (snakemake --configfile FILE.yaml)")
    args = parser.parse_args()

    config = workflow_config()
    priors = prior_checkpoints(args.prior)
    config["illumination_prior"]["checkpoints"].update(priors)
    if (args.dev or args.held_out) and not args.panoramas:
        parser.error("--dev and --held-out: pass --panoramas DIR")
    if args.dev and args.held_out:
        parser.error("--dev or --held-out, not both")
    args.work = args.work or (DEV_WORK if args.dev else HELD_OUT_WORK if args.held_out else WORK)
    available = real_light_scenes(args.panoramas, DEV_SCENES) if args.dev else \
        real_light_scenes(args.panoramas, HELD_OUT_LIGHT_SCENES) if args.held_out else \
        {**POSTERIOR_SCENES, **(real_light_scenes(args.panoramas) if args.panoramas else {})}
    wanted = args.scenes or list(available)
    missing = [name for name in wanted if name not in available]
    if missing:
        parser.error(f"scenes {', '.join(missing)} are lit by real panoramas: pass --panoramas DIR")
    scenes = {name: available[name] for name in wanted}
    jobs = method_jobs(args.work, scenes, args.methods, args.seeds, config, dps_variants(config, args.dps),
                       args.samplers, args.rerun)
    if priors:  # the priors' name joins the dps label: rows and sample folders apart from the shipped prior's
        label = "+".join(sorted({Path(checkpoint).stem.split("_", 1)[-1] for checkpoint in priors.values()}))
        jobs = [replace(job, sampler=f"{job.sampler}@{label}") if job.method == "dps" else job for job in jobs]
    if args.workflow:
        write_workflow(jobs, args.workflow)
        return
    rows = run_study(jobs, args.out, SAMPLE_COLUMNS, run_job, args.jobs)
    print("\n".join(summary(rows)))


if __name__ == "__main__":
    main()
