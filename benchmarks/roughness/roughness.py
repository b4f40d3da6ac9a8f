"""Env-map diversity of `dps` samples against material roughness (the paper's Fig. 9), over repeats.

One object at each roughness (dpi.studies.scenes.roughness_scenes: metallic up to roughness 0.1, dielectric above)
under the same natural light; each repeat is its own capture (render noise) and initialisation, and draws
`--samples` dps samples from its own seed stream with the shipped outdoor prior (`--steps` respaced steps, every
roughness the same number: the adaptive step cut is off), through the study engine. One row per (roughness, repeat)
in benchmarks/roughness/roughness.csv (roughness, metallic, repeat, samples, env_sigma2_sample), the plot
beside it; it prints mean +- std per roughness.

    .venv/bin/python benchmarks/roughness/roughness.py [--roughness 0.05 0.2 0.5 0.9] [--repeats 3] [--jobs 2]

Samples already drawn are reused; rows already in the CSV with the same settings hash are kept.
`--workflow FILE.yaml` writes the same sweep as a workflow config instead (the report shows the curve).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from dpi.studies.engine import (Job, append_row, pool, prepare_job, read_rows, results_csv, run_job, work_dir,
                                workflow_config, write_workflow)
from dpi.studies.scenes import repeat_scene, repeat_synth, roughness_scenes

WORK = work_dir("roughness_study")
CSV = results_csv("roughness")
COLUMNS = ("roughness", "metallic", "repeat", "samples", "env_sigma2_sample")
MAP_HEIGHT = 32
"""rows of the fitted map: the object's 32 px views see no finer light"""
REFINE = 20
"""refinement iterations of each sample"""


def point_jobs(args: argparse.Namespace, config: dict) -> dict[tuple[float, int], list[Job]]:
    """(roughness, repeat) -> the dps jobs of its samples."""
    method_cfg = {"steps": args.steps, "refine": {"iterations": REFINE}}
    groups = {}
    for scene, synth in roughness_scenes(args.roughness).items():
        for repeat in range(args.repeats):
            name, own = repeat_scene(scene, repeat), repeat_synth(synth, repeat)
            groups[(synth["roughness"], repeat)] = [Job(WORK, name, "roughness", own, "dps", "", 1000 * repeat + k,
                                                        method_cfg, config) for k in range(args.samples)]
    return groups


def current_rows(args: argparse.Namespace, config: dict) -> list[dict[str, Any]]:
    """Every roughness point in the CSV drawn with these settings (the figure shows them all, not only this run's)."""
    rows = read_rows(args.out, ())
    every = argparse.Namespace(**{**vars(args), "roughness": sorted({r["roughness"] for r in rows})})
    keyed = {(*key, jobs[0].settings_hash) for key, jobs in point_jobs(every, config).items()}
    return [r for r in rows if (r["roughness"], int(r["repeat"]), r["settings_hash"]) in keyed]


def point_row(key: tuple[float, int], jobs: list[Job]) -> dict[str, Any]:
    """The study's row of one (roughness, repeat): the spread of its samples' maps."""
    from dpi.io.exr import read_exr
    from dpi.solve.spread import normalized_env, sample_variance

    envs = [read_exr(job.layout.scene(job.scene).sample_files(job.label, job.seed)["env"]) for job in jobs]
    return {"roughness": key[0], "metallic": jobs[0].synth["metallic"], "repeat": key[1], "samples": len(jobs),
            "env_sigma2_sample": sample_variance([normalized_env(e) for e in envs])}


def plot(rows: list[dict[str, float]], path: Path) -> None:
    """sigma2_sample per roughness: each repeat as a dot, the mean as a line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4.5, 3.2), dpi=120)
    xs = sorted({r["roughness"] for r in rows})
    means = [np.mean([r["env_sigma2_sample"] for r in rows if r["roughness"] == x]) for x in xs]
    ax.plot(xs, means, "-", color="C0", label="mean")
    ax.plot([r["roughness"] for r in rows], [r["env_sigma2_sample"] for r in rows], "o", color="C0", alpha=0.5,
            label="repeat")
    ax.set_xlabel("roughness")
    ax.set_ylabel("env $\\sigma^2_{sample}$")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--roughness", type=float, nargs="+", default=[0.05, 0.2, 0.5, 0.9])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--samples", type=int, default=6,
                        help="dps samples per point: a variance from n samples has a relative variance of 2 / (n - 1)")
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--jobs", type=int, default=2, help="samples drawn side by side (1 thread each)")
    parser.add_argument("--out", type=Path, default=CSV)
    parser.add_argument("--workflow", type=Path, default=None, metavar="FILE.yaml",
                        help="write the study as a workflow config instead (snakemake --configfile FILE.yaml)")
    args = parser.parse_args()

    config = {**workflow_config(env_height=MAP_HEIGHT), "adaptive": {"sample_stop": False, "diffuse_steps": False}}
    groups = point_jobs(args, config)
    if args.workflow:
        write_workflow([job for jobs in groups.values() for job in jobs], args.workflow)
        return
    keyed = {(*key, jobs[0].settings_hash): jobs for key, jobs in groups.items()}
    done = {(r["roughness"], int(r["repeat"]), r["settings_hash"]) for r in read_rows(args.out, ())}
    todo = {k: v for k, v in keyed.items() if k not in done}
    start = time.perf_counter()
    print(f"{len(todo)} points to draw ({sum(len(v) for v in todo.values())} samples)", flush=True)
    with pool(max(args.jobs, 1)) as workers:
        list(workers.map(prepare_job, list({j.scene: j for jobs in todo.values() for j in jobs}.values())))
        for key, jobs in todo.items():
            list(workers.map(run_job, jobs))
            append_row(args.out, point_row(key[:2], jobs), COLUMNS, key[2])
    rows = current_rows(args, config)
    plot(rows, args.out.with_suffix(".png"))
    print(f"{args.repeats} repeats x {args.samples} dps samples per roughness, {args.steps} steps, "
          f"{time.perf_counter() - start:.0f} s")
    print(f"{'roughness':>9} {'metallic':>8} {'env sigma2_sample (mean +- std over repeats)':>46}")
    for r in args.roughness:
        values = np.array([row["env_sigma2_sample"] for row in rows if row["roughness"] == r])
        metallic = next(row["metallic"] for row in rows if row["roughness"] == r)
        print(f"{r:>9.3f} {metallic:>8.1f} {values.mean():>37.5f} +- {values.std():.5f}")


if __name__ == "__main__":
    main()
