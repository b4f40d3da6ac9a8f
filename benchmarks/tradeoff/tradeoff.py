"""Run time of one `dps` sample against env-map, albedo and novel-view error, over the cost knobs.

On the demo object (the demo's synthetic capture; other image resolutions are rendered into
results/benchmarks/captures), starting from one path-traced initialisation (resampled to each
env-map and texture size), one knob at a time is varied around the base setting: diffusion steps,
render spp, image resolution, pixels of the recorded light transport, env-map height, texture size and material refinement
iterations; then the quality presets of dpi's config. Prints seconds per sample and the errors,
marks the Pareto front (time vs env PSNR, albedo MSE and view PSNR), and writes the table (CSV)
and a plot.

    .venv/bin/python benchmarks/tradeoff/tradeoff.py [--knobs steps spp ...] [--presets draft default] [--threads 2]
"""

from __future__ import annotations

import argparse
import csv
import time
from dataclasses import asdict, replace
from pathlib import Path

from dpi.capture import load_capture
from dpi.evaluation.sample_metrics import evaluate_sample
from dpi.io.layout import INIT, INIT_TRACE
from dpi.prior.sample import load_scene_prior
from dpi.render.renderer import RenderConfig
from dpi.solve.dps import dps_sample
from dpi.solve.init import path_traced_init
from dpi.solve.problem import InverseProblem, ProblemConfig
from dpi.studies.demo_costs import DEMO, Setting, capture_at, demo_pipeline, preset_setting
from dpi.studies.engine import PROVENANCE, current_commit, results_csv, settings_hash
from dpi.studies.pareto import pareto_front

OUT = demo_pipeline().layout.results / "benchmarks"
PIPELINE = demo_pipeline()
SWEEPS = {"steps": [25, 50, 100, 250, 1000], "spp": [4, 16, 64], "resolution": [32, 64],
          "transport_pixels": [1024, 2048, 4096], "env_height": [16, 32, 64], "texture_size": [32, 64, 128],
          "refine_iterations": [25, 100, 200]}


def run(setting: Setting, init_dir: Path, prior, threads: int, seed: int) -> dict[str, float]:
    """One dps sample at `setting`: seconds and errors against ground truth and held-out views."""
    capture = load_capture(capture_at(setting.resolution, threads, OUT))
    problem = InverseProblem(capture, ProblemConfig(env_height=setting.env_height, texture_size=setting.texture_size),
                             RenderConfig(spp=setting.spp, threads=threads))
    init = problem.load_decomposition(init_dir)
    base = PIPELINE.method_settings("dps")
    cfg = replace(base, steps=setting.steps, refine=replace(base.refine, iterations=setting.refine_iterations),
                  proximal=replace(base.proximal, transport=replace(base.proximal.transport,
                                                                     pixels=setting.transport_pixels)))
    start = time.perf_counter()
    result = dps_sample(problem, prior, init, cfg, seed=seed, progress=False).decomposition
    seconds = time.perf_counter() - start
    m = evaluate_sample(problem, result, spp=PIPELINE.evaluate_spp, seed=1, seconds=seconds)
    return {"seconds": seconds, "env_psnr": m["env_psnr"], "albedo_mse": m["albedo_mse"], "view_psnr": m["novel_psnr"]}


def plot(rows: list[dict], front: list[bool], path: Path) -> None:
    """Seconds per sample against each error, Pareto-front settings highlighted."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for ax, key, label in zip(axes, ("env_psnr", "albedo_mse", "view_psnr"),
                              ("env-map PSNR (dB)", "albedo MSE", "held-out view PSNR (dB)")):
        for row, best in zip(rows, front):
            ax.scatter(row["seconds"], row[key], c="tab:red" if best else "tab:gray", s=30 if best else 14)
            ax.annotate(row["label"], (row["seconds"], row[key]), fontsize=6, xytext=(3, 2), textcoords="offset points")
        ax.set_xscale("log")
        ax.set_xlabel("seconds per dps sample")
        ax.set_ylabel(label)
    fig.suptitle("dps run time vs error on the demo (red: Pareto front)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--knobs", nargs="*", default=list(SWEEPS), choices=list(SWEEPS))
    parser.add_argument("--values", nargs="*", default=[], metavar="KNOB=V1,V2",
                        help="replace a knob's swept values, e.g. steps=25,100")
    parser.add_argument("--presets", nargs="*", default=["draft", "default"],
                        help="quality presets of dpi's config to measure too (paper: 1000 steps, meant for a GPU)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    base = preset_setting()
    demo = load_capture(capture_at(base.resolution, args.threads, OUT))
    init_dir = OUT / f"tradeoff_{INIT}"
    if not (init_dir / INIT_TRACE).exists():
        problem = InverseProblem(demo, ProblemConfig(base.env_height, base.texture_size),
                                 RenderConfig(spp=base.spp, threads=args.threads))
        problem.save_decomposition(path_traced_init(problem, PIPELINE.init_settings, seed=0, progress=False).kept,
                                   init_dir, INIT_TRACE)
    prior = load_scene_prior(demo.options, PIPELINE.prior_checkpoint(DEMO))

    sweeps = {**SWEEPS, **{k: [int(v) for v in vs.split(",")] for k, vs in (a.split("=") for a in args.values)}}
    todo: dict[Setting, str] = {base: "base"}
    for knob in args.knobs:
        for value in sweeps[knob]:
            todo.setdefault(replace(base, **{knob: value}), f"{knob}={value}")
    for name in args.presets:
        setting = preset_setting(name)
        todo[setting] = f"{todo[setting]} = {name}" if setting in todo else name

    print(f"dps on the demo, {args.threads} threads, base {asdict(base)}")
    print(f"{'setting':<26} {'s/sample':>9} {'env PSNR':>9} {'albedo MSE':>11} {'view PSNR':>10}")
    rows = []
    for setting, label in todo.items():
        row = {"label": label, **asdict(setting), **run(setting, init_dir, prior, args.threads, args.seed),
               "commit": current_commit(), "settings_hash": settings_hash({**asdict(setting), "seed": args.seed})}
        rows.append(row)
        print(f"{label:<26} {row['seconds']:>9.1f} {row['env_psnr']:>9.2f} {row['albedo_mse']:>11.5f} "
              f"{row['view_psnr']:>10.2f}", flush=True)
    front = pareto_front(rows, minimize=("seconds", "albedo_mse"), maximize=("env_psnr", "view_psnr"))
    print("Pareto front (no other setting is faster and at least as accurate on every error):")
    for row, best in zip(rows, front):
        if best:
            print(f"  {row['label']}: {row['seconds']:.1f} s, env {row['env_psnr']:.2f} dB, "
                  f"albedo {row['albedo_mse']:.5f}, view {row['view_psnr']:.2f} dB")
    table = results_csv("tradeoff")
    with open(table, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=[*(k for k in rows[0] if k not in PROVENANCE), "pareto", *PROVENANCE])
        writer.writeheader()
        writer.writerows({**row, "pareto": best} for row, best in zip(rows, front))
    OUT.mkdir(parents=True, exist_ok=True)
    plot(rows, front, OUT / "tradeoff.png")
    print(f"wrote {table} and {OUT / 'tradeoff.png'}")


if __name__ == "__main__":
    main()
