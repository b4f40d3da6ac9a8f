"""The written sun's size the training views chose (dpi.solve.dps.sun_size), per dps sample with a sun.

    .venv/bin/python benchmarks/sun_size/sun_size.py RESULTS_DIR [RESULTS_DIR ...] [--out benchmarks/sun_size/sun_size.csv]

Each RESULTS_DIR is a workflow's results folder (results/{scene}/dps/{k}/trace.json, eval/dps/{k}.json). A row per
sample whose map has a parametric sun: the radius written, the training views' loss at the sun's own radius and
at the chosen one (the trace's candidates, path traced at the renderer's spp), and the evaluation's training fit over
the truth's and env PSNR. Rows of the scenes read are replaced, the others kept; it prints the rows.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from dpi.light.sunlight import SUN_RADIUS_DEG
from dpi.studies.engine import read_rows, results_csv, write_rows

TEXT = ("scene",)


def sample_rows(results: Path) -> list[dict]:
    """The rows of one results folder (module notes)."""
    rows = []
    for trace_path in sorted(results.glob("*/dps/*/trace.json")):
        scene, k = trace_path.parts[-4], int(trace_path.parts[-2])
        sun = json.loads(trace_path.read_text())["info"].get("sun")
        evaluation = results / scene / "eval" / "dps" / f"{k}.json"
        if not sun or "radius_losses" not in sun or not evaluation.exists():
            continue
        metrics = json.loads(evaluation.read_text())["metrics"]
        losses = sun["radius_losses"]
        own, chosen = losses[f"{SUN_RADIUS_DEG:g}"], losses[f"{sun['radius_deg']:g}"]
        rows.append({"scene": scene, "seed": k, "radius_deg": sun["radius_deg"], "loss_own": own, "loss_chosen": chosen,
                     "loss_ratio": chosen / own, "train_fit_over_truth": metrics["train_fit_over_truth"],
                     "env_psnr": metrics["env_psnr"], "novel_psnr": metrics["novel_psnr"]})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("results", nargs="+", type=Path, help="workflow results folders")
    parser.add_argument("--out", type=Path, default=results_csv("sun_size"))
    args = parser.parse_args()
    new = [row for folder in args.results for row in sample_rows(folder)]
    scenes = {row["scene"] for row in new}
    rows = [r for r in read_rows(args.out, TEXT) if r["scene"] not in scenes] + new
    if rows:
        write_rows(args.out, rows, settings="")
    for row in new:
        print(" ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()))


if __name__ == "__main__":
    main()
