"""Real photo capture end to end: the skull photos (tests/data/skull_photos) through the whole workflow.

Runs Snakemake on the capture from its photos and cameras (masks, geometry, UVs, init, `dps` and `none`
samples, evaluation, report), then scores what a user sees: the poses the capture's cameras came from (the
`poses` stage's own summary, `poses_summary.json`, fitted at 2400 px, the size COLMAP needs on these photos),
each derived mask's IoU against the hand-checked one (`checked_masks/`, the skull without its stand), the views
the masks' witnesses flagged (and how they judged the checked views: those under 0.8 IoU flagged, those over 0.9
flagged), and the held-out views' PSNR per method. One row per run goes to benchmarks/results/real_photos.csv.

    .venv/bin/python benchmarks/real_photos.py [--cores 2] [--samples 2] [--stereo]
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml

from dpi.capture.consistency import mask_iou
from dpi.io.images import read_mask
from dpi.preprocess.accuracy import flag_counts
from dpi.studies.engine import CHECKOUT as ROOT
from dpi.studies.engine import append_row, read_rows, results_csv, settings_hash, work_dir

CAPTURE = ROOT / "tests" / "data" / "skull_photos"
SCENE = CAPTURE.name
WORK = work_dir("real_photos")
CSV = results_csv("real_photos")
METHODS = ("init", "dps", "none")
COLUMNS = ("capture", "views", "size", "registered", "reprojection_px", "mask_iou", "mask_iou_min",
           "masks_flagged", "masks_below_08", "flagged_below_08", "flagged_above_09",
           *(f"{m}_view_psnr" for m in METHODS), "seconds")


def mask_scores(masks: Path, checked: Path) -> dict[str, float]:
    """IoU of each derived mask against its hand-checked twin, by view name."""
    return {p.stem: mask_iou(read_mask(masks / p.name), read_mask(p)) for p in sorted(checked.glob("*.png"))}


def held_out_psnr(summary: Path) -> dict[str, float]:
    """Mean held-out view PSNR per method of a run's summary.csv."""
    return {row["method"]: row["novel_psnr"] for row in read_rows(summary)}


def run_workflow(config: dict, cores: int) -> float:
    """Seconds of one Snakemake run of `config` from an empty results folder; Snakemake's log beside it."""
    shutil.rmtree(WORK / "results", ignore_errors=True)
    path = WORK / "config.yaml"
    path.write_text(yaml.safe_dump(config))
    start = time.perf_counter()
    with open(WORK / "snakemake.log", "w") as log:
        subprocess.run([sys.executable, "-m", "snakemake", "--cores", str(cores), "--configfile", str(path)],
                       cwd=ROOT, check=True, stdout=log, stderr=subprocess.STDOUT)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cores", type=int, default=2)
    parser.add_argument("--samples", type=int, default=2, help="posterior samples per method")
    parser.add_argument("--stereo", action="store_true", help="carve with multi-view stereo too (minutes more)")
    args = parser.parse_args()
    WORK.mkdir(parents=True, exist_ok=True)
    config = {"scenes": [SCENE], "captures_dir": str(CAPTURE.parent), "results_dir": str(WORK / "results"),
              "methods": [m for m in METHODS if m != "init"], "samples": args.samples,
              "preprocess": {"geometry": {"stereo": args.stereo}}}
    seconds = run_workflow(config, args.cores)
    results = WORK / "results"
    ious = mask_scores(results / SCENE / "masks", CAPTURE / "checked_masks")
    flagged = json.loads((results / SCENE / "masks" / "summary.json").read_text()).get("unreliable", [])
    poses = json.loads((CAPTURE / "poses_summary.json").read_text())
    psnr = held_out_psnr(results / "eval" / "summary.csv")
    size = read_mask(next((results / SCENE / "masks").glob("*.png"))).shape
    row = {"capture": SCENE, "views": len(ious), "size": f"{size[1]}x{size[0]}",
           "registered": poses["registered"] / poses["images"], "reprojection_px": poses["mean_reprojection_error_px"],
           "mask_iou": float(np.mean(list(ious.values()))), "mask_iou_min": min(ious.values()),
           "masks_flagged": len(flagged), **flag_counts(list(ious.values()), [v in flagged for v in ious]),
           **{f"{m}_view_psnr": psnr.get(m, float("nan")) for m in METHODS},
           "seconds": seconds}
    append_row(CSV, row, COLUMNS, settings_hash(config))
    worst = sorted(ious, key=ious.get)[:3]
    print(yaml.safe_dump({**row, "worst_masks": {v: round(ious[v], 3) for v in worst}, "flagged": flagged},
                         sort_keys=False))


if __name__ == "__main__":
    main()
