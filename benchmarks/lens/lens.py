"""Lens study: does a capture taken through a lens fit as well as its pinhole twin once dpi undistorts it?

A synthetic capture (pinhole, with ground truth) is copied three times: `pinhole` as rendered; `undistorted`
with every image and mask distorted by a known barrel lens (k1, k2) and the lens written into its
transforms.json, so the capture stage undistorts it (dpi.capture.undistort); `ignored` distorted the same way but
without the coefficients, as a user who drops them would run it. Each gets its own initialisation through
the workflow's stage functions, scored on the held-out views. Rows per (variant, seed) go to
benchmarks/lens/lens.csv; it prints mean +- std per variant.

    .venv/bin/python benchmarks/lens/lens.py [--seeds 0 1 2] [--k1 -0.15] [--k2 0.04]
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import numpy as np

from dpi.capture.cameras import Lens, read_cameras
from dpi.capture.undistort import distort_image
from dpi.io.exr import write_exr
from dpi.io.images import read_image, read_mask, write_mask
from dpi.io.layout import Layout
from dpi.stages import capture_stage, evaluate_stage, init_stage
from dpi.studies.engine import (Job, append_row, mean_std_cells, prepare_capture, read_rows, results_csv, settings_hash,
                                work_dir, workflow_config)
from dpi.studies.scenes import SIZE

WORK = work_dir("lens_study")
CSV = results_csv("lens")
COLUMNS = ("variant", "seed", "k1", "k2", "novel_psnr", "env_psnr", "albedo_mse")
VARIANTS = ("pinhole", "undistorted", "ignored")
CAPTURE = {**SIZE, "views": 12, "held_out_every": 4, "width": 64, "height": 64, "shape": "blob",
           "roughness": 0.4, "metallic": 0.0, "environment": "outdoor", "environment_seed": 41, "prior": "outdoor"}


def distorted_twin(source: Path, target: Path, lens: Lens, declare: bool) -> None:
    """A copy of a capture whose images and masks came through `lens` (declared in transforms.json or not)."""
    shutil.rmtree(target, ignore_errors=True)
    shutil.copytree(source, target)
    cameras = read_cameras(source / "transforms.json")
    for name, camera in cameras.items():
        write_exr(target / "images" / f"{name}.exr", distort_image(read_image(source / "images" / f"{name}.exr"),
                                                                   camera, lens))
        for mask in (target / "masks").glob(f"{name}.png"):
            write_mask(mask, distort_image(read_mask(mask).astype(np.float32), camera, lens) > 0.5)
    if declare:
        data = json.loads((target / "transforms.json").read_text())
        data.update({k: v for k, v in lens.to_json().items() if k != "camera_model"})
        (target / "transforms.json").write_text(json.dumps(data, indent=1))


def run(seed: int, lens: Lens, config: dict) -> list[dict]:
    """The three variants of one seed's capture: their init's held-out view PSNR, env PSNR and albedo MSE."""
    root = WORK / f"seed{seed}"
    layout = Layout.of_study(root)
    prepare_capture(root, "pinhole", {**CAPTURE, "seed": seed}, threads=2)
    for variant in VARIANTS[1:]:
        distorted_twin(layout.capture_dir("pinhole"), layout.capture_dir(variant), lens, variant == "undistorted")
        shutil.copy(layout.synth_marker("pinhole"), layout.synth_marker(variant))
    rows = []
    for variant in VARIANTS:
        job = Job(root, variant, "", {**CAPTURE, "seed": seed}, "init", "", 0, {}, config).stage_job(threads=2)
        capture_stage(job)
        init_stage(job)
        evaluate_stage(job)
        metrics = json.loads(job.evaluation.read_text())["metrics"]
        rows.append({"variant": variant, "seed": seed, "k1": lens.k1, "k2": lens.k2,
                     **{k: metrics[k] for k in COLUMNS[4:]}})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2])
    parser.add_argument("--k1", type=float, default=-0.15)
    parser.add_argument("--k2", type=float, default=0.04)
    parser.add_argument("--out", type=Path, default=CSV)
    args = parser.parse_args()
    lens, config = Lens(k1=args.k1, k2=args.k2), workflow_config(env_height=16)
    settings = settings_hash({"capture": CAPTURE, "lens": lens.to_json(), "init": config["init"],
                              "problem": config["problem"], "render": config["render"]})
    done = {(r["variant"], int(r["seed"])) for r in read_rows(args.out, ("variant",)) if r["settings_hash"] == settings}
    for seed in args.seeds:
        if all((v, seed) in done for v in VARIANTS):
            continue
        for row in run(seed, lens, config):
            append_row(args.out, row, COLUMNS, settings)
            print("  ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()), flush=True)
    rows = [r for r in read_rows(args.out, ("variant",)) if r["settings_hash"] == settings]
    print(f"{'variant':<12} {'n':>2} {'view PSNR':>16} {'env PSNR':>16} {'albedo MSE':>18}")
    for variant in VARIANTS:
        sel = [r for r in rows if r["variant"] == variant]
        cells = mean_std_cells(sel, (("novel_psnr", ".2f"), ("env_psnr", ".2f"), ("albedo_mse", ".4f")))
        print(f"{variant:<12} {len(sel):>2} " + " ".join(f"{c:>16}" for c in cells))


if __name__ == "__main__":
    main()
