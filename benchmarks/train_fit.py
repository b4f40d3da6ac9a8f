"""How well each sample of a study re-renders its training views, against the initialisation's fit.

A decomposition is a sample of the posterior only if it explains the photos: issue 31 asks that no
sample fits the training views worse than the init does. For every sample folder of a study (the
posterior or the calibration study's results), this renders the scene's training views at `--spp`
and compares the foreground mean squared error with the init's (same renders, same seeds), then
prints per method and sampler: the samples, the mean ratio to the init's MSE, and how many exceed it.

    .venv/bin/python benchmarks/train_fit.py results/benchmarks/calibration_study [--spp 64] [--out CSV]
        [--methods none dps_proximal]
"""

from __future__ import annotations

import argparse
import csv
from collections import defaultdict
from pathlib import Path

import numpy as np
import torch

from dpi.layout import INIT
from dpi.stages import SolveSettings, load_problem

TOLERANCE = 1.05
"""a sample counts as fitting worse than the init when its MSE exceeds the init's by more than this factor
(the renders' own noise at 64 spp is a few percent of the MSE)"""


def training_mse(problem, decomposition, spp: int) -> float:
    """Foreground mean squared error of the training views re-rendered with a decomposition."""
    with torch.no_grad():
        return float(np.mean([float(problem.view_loss(problem.render(decomposition.env, decomposition.materials, v,
                                                                     seed=17 + v, spp=spp), v))
                              for v in problem.train_ids]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("root", type=Path, help="a study folder (it holds results/{scene}/...)")
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=None, help="CSV of every sample's MSE and its init's")
    parser.add_argument("--methods", nargs="*", default=None,
                        help="method folders to score (e.g. none dps_proximal; default: all)")
    args = parser.parse_args()

    from posterior_study import study_layout, workflow_config

    config = workflow_config()
    layout = study_layout(args.root)
    rows = []
    for capture_json in sorted(args.root.glob("results/*/capture.json")):
        scene = capture_json.parent.name
        files = layout.scene(scene)
        problem = load_problem(capture_json, SolveSettings.from_config(config, threads=args.threads))
        init = training_mse(problem, problem.load_decomposition(files.sample_dir(INIT)), args.spp)
        for method_dir in sorted(p for p in capture_json.parent.iterdir() if p.is_dir() and p.name not in
                                 (INIT, "eval", "logs", "benchmarks", "working")
                                 and (args.methods is None or p.name in args.methods)):
            for sample in sorted(p for p in method_dir.iterdir() if (p / "envmap.exr").is_file()):
                mse = training_mse(problem, problem.load_decomposition(sample), args.spp)
                rows.append({"scene": scene, "method": method_dir.name, "sample": sample.name, "mse": mse,
                             "init_mse": init})
    if args.out:
        with open(args.out, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    groups = defaultdict(list)
    for row in rows:
        groups[row["method"]].append(row["mse"] / row["init_mse"])
    print(f"{'method':<16} {'samples':>7} {'MSE / init MSE':>16} {'worse than init':>16}")
    for method, ratios in sorted(groups.items()):
        worse = sum(r > TOLERANCE for r in ratios)
        print(f"{method:<16} {len(ratios):>7} {np.mean(ratios):>10.2f} +- {np.std(ratios):.2f} {worse:>9} of {len(ratios)}")


if __name__ == "__main__":
    main()
