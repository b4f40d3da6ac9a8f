"""How well each sample of a study re-renders its training views, against the initialisation's fit.

A decomposition is a sample of the posterior only if it explains the photos: issue 31 asks that no
sample fits the training views worse than the init does. For every sample folder of a study (the
posterior or the calibration study's results), this renders the scene's training views at `--spp`
and compares the foreground mean squared error (in the data term's log(1 + x) space) with the
init's (same renders, same seeds), then prints per method and sampler: the samples, the mean ratio to the
init's MSE, and how many exceed it. Where the capture has its ground truth (gt/), the truth's own MSE is the
other yardstick: the truth and an exact posterior sample are alike given the photos, so they fit the views
equally well on average, while the init, a free fit, can land on either side of them; each method's ratio to
the truth's MSE, and how many exceed it, are printed too.

    .venv/bin/python benchmarks/train_fit.py results/benchmarks/calibration_study [--spp 1024] [--out CSV]
        [--methods none dps_proximal] [--scenes blob_glossy]
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import numpy as np

from dpi.evaluation.train_fit import ground_truth as truth
from dpi.evaluation.train_fit import training_fit
from dpi.io.layout import INIT, Layout
from dpi.solve.problem import SolveConfig
from dpi.stages import load_problem

TOLERANCE = 1.05
"""a sample counts as fitting worse than the init when its MSE exceeds the init's by more than this factor
(the estimate's spread at SPP)"""
SPP = 1024
"""samples per pixel of each of a view's two re-renders (dpi.evaluation.train_fit removes their noise; more
samples make the estimate steadier)"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("root", type=Path, help="a study folder (it holds results/{scene}/...)")
    parser.add_argument("--spp", type=int, default=SPP)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=None, help="CSV of every sample's MSE and its init's")
    parser.add_argument("--methods", nargs="*", default=None,
                        help="method folders to score (e.g. none dps_proximal; default: all)")
    parser.add_argument("--scenes", nargs="*", default=None, help="scenes to score (default: all)")
    args = parser.parse_args()

    from dpi.studies.engine import settings_hash, workflow_config, write_rows

    config = workflow_config()
    layout = Layout.of_study(args.root)
    rows = []
    for capture_json in sorted(args.root.glob("results/*/capture.json")):
        scene = capture_json.parent.name
        if args.scenes is not None and scene not in args.scenes:
            continue
        files = layout.scene(scene)
        problem = load_problem(capture_json, SolveConfig.from_config(config, threads=args.threads))
        init = training_fit(problem, problem.load_decomposition(files.sample_dir(INIT)), args.spp, 17)
        reference = truth(problem)
        truth_mse = training_fit(problem, reference, args.spp, 17) if reference is not None else float("nan")
        for method_dir in sorted(p for p in capture_json.parent.iterdir() if p.is_dir() and p.name not in
                                 (INIT, "eval", "logs", "benchmarks", "working")
                                 and (args.methods is None or p.name in args.methods)):
            for sample in sorted(p for p in method_dir.iterdir() if (p / "envmap.exr").is_file()):
                mse = training_fit(problem, problem.load_decomposition(sample), args.spp, 17)
                rows.append({"scene": scene, "method": method_dir.name, "sample": sample.name, "mse": mse,
                             "init_mse": init, "truth_mse": truth_mse})
    if args.out:
        write_rows(args.out, rows, settings_hash({"spp": args.spp, "config": {k: config[k] for k in
                                                                              ("problem", "render", "evaluate")}}))
    for scene in sorted({row["scene"] for row in rows}):
        row = next(r for r in rows if r["scene"] == scene)
        print(f"{scene}: truth MSE / init MSE {row['truth_mse'] / row['init_mse']:.2f}")
    groups = defaultdict(list)
    for row in rows:
        groups[row["method"]].append((row["mse"] / row["init_mse"], row["mse"] / row["truth_mse"]))
    print(f"{'method':<16} {'samples':>7} {'MSE / init MSE':>16} {'worse than init':>16} {'MSE / truth MSE':>16} "
          f"{'worse than truth':>17}")
    for method, pairs in sorted(groups.items()):
        init_ratio, truth_ratio = np.array(pairs).T
        print(f"{method:<16} {len(pairs):>7} {init_ratio.mean():>10.2f} +- {init_ratio.std():.2f} "
              f"{sum(init_ratio > TOLERANCE):>9} of {len(pairs)} {truth_ratio.mean():>10.2f} +- {truth_ratio.std():.2f} "
              f"{sum(truth_ratio > TOLERANCE):>10} of {len(pairs)}")


if __name__ == "__main__":
    main()
