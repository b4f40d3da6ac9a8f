"""Real photo captures end to end through the whole workflow: the skull photos (tests/data/skull_photos, with
their cameras) and the saharov32 statue in a busy street (../shared/captures/saharov32: photos only).

Runs Snakemake on a capture (masks, geometry, UVs, init, `dps` and `none` samples, evaluation, report; for a
photos-only capture the poses too, its photos and a scene.yaml copied into the study folder), then scores what a
user sees: the poses (the `poses` stage's summary: the skull's `poses_summary.json`, fitted at 2400 px, the size
COLMAP needs on those photos; against a published solution where the capture has one, `reference_cameras.out`:
rotation and centre errors after one similarity, dpi.preprocess.accuracy.pose_errors), each derived mask's IoU
against the hand-checked one, the views the masks' witnesses flagged (and how they judged the checked views: those
under 0.8 and under 0.9 IoU flagged, those over 0.9 flagged), the stages' seconds and the held-out views' PSNR
per method. A run that stops (the masks judged unusable) is scored as far as it got and says where it stopped. One
row per run goes to benchmarks/real_photos/real_photos.csv: the defaults a user gets, or a named variant.

    .venv/bin/python benchmarks/real_photos/real_photos.py [--capture skull_photos|saharov32] [--captures ../shared/captures]
        [--cores 2] [--samples 2] [--variant defaults|no_stereo]
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from dpi.capture.bundler import bundler_cameras, read_bundler
from dpi.capture.cameras import read_cameras
from dpi.capture.consistency import mask_iou
from dpi.io.images import exif_orientation, ldr_header_size, read_mask
from dpi.io.layout import SceneLayout
from dpi.preprocess.accuracy import flag_counts, pose_errors
from dpi.studies.engine import CHECKOUT as ROOT
from dpi.studies.engine import append_row, read_rows, results_csv, settings_hash, work_dir

WORK = work_dir("real_photos")
CSV = results_csv("real_photos")
METHODS = ("init", "dps", "none")
STAGES = ("poses", "masks", "geometry", "uv")
VARIANTS = {"defaults": {}, "no_stereo": {"preprocess": {"geometry": {"stereo": False}}}}
"""the settings each named run changes from the defaults a user gets"""
COLUMNS = ("capture", "variant", "views", "size", "registered", "reprojection_px", "reference_reprojection_px",
           "rotation_error_deg", "centre_error", "mask_iou", "mask_iou_min", "masks_flagged", "masks_below_08",
           "flagged_below_08", "masks_below_09", "flagged_below_09", "flagged_above_09",
           *(f"{s}_seconds" for s in STAGES),
           *(f"{m}_view_psnr" for m in METHODS), "seconds", "stopped")


@dataclass(frozen=True)
class RealCapture:
    """A real capture the benchmark scores: its folder, its hand-checked masks' folder (relative to it), its poses'
    summary when its cameras are given (else the poses stage's), and a published camera solution, if any."""

    folder: Path
    checked: str
    photos_only: bool
    poses_summary: str | None = None
    reference_cameras: str | None = None
    prior: str = "outdoor"
    held_out_every: int = 0
    """a photos-only capture's scene.yaml holds every n-th photo out (from the middle of the first n; 0: none), for
    the methods' held-out views"""


def captures(shared: Path) -> dict[str, RealCapture]:
    return {"skull_photos": RealCapture(ROOT / "tests" / "data" / "skull_photos", "checked_masks", False,
                                        poses_summary="poses_summary.json"),
            "saharov32": RealCapture(shared / "saharov32", "reference_masks", True,
                                     reference_cameras="reference_cameras.out", held_out_every=8)}


def mask_scores(masks: Path, checked: Path) -> dict[str, float]:
    """IoU of each derived mask against its hand-checked twin, by view name."""
    return {p.stem: mask_iou(read_mask(masks / p.name), read_mask(p)) for p in sorted(checked.glob("*.png"))
            if (masks / p.name).is_file()}


def held_out_psnr(summary: Path) -> dict[str, float]:
    """Mean held-out view PSNR per method of a run's summary.csv (none before the run's evaluation)."""
    return {row["method"]: row["novel_psnr"] for row in read_rows(summary)} if summary.is_file() else {}


def reference_errors(capture: RealCapture, cameras_json: Path) -> dict[str, float]:
    """Rotation (degrees) and camera-centre errors (fraction of the orbit's radius) of the derived cameras against
    the published solution, after one similarity, and that solution's own mean reprojection error (pixels, on its
    points under its lens: how far it is itself from the photos); NaN without one."""
    if not capture.reference_cameras or not cameras_json.is_file():
        return {"rotation_error_deg": float("nan"), "centre_error": float("nan"),
                "reference_reprojection_px": float("nan")}
    photos = sorted(p for p in (capture.folder / "images").iterdir() if p.is_file())
    path = capture.folder / capture.reference_cameras
    reference = bundler_cameras(path, [p.stem for p in photos], ldr_header_size(photos[0]), exif_orientation(photos[0]))
    errors = pose_errors(read_cameras(cameras_json), reference)
    return {"rotation_error_deg": errors["rotation_error_deg_max"], "centre_error": errors["centre_error_max"],
            "reference_reprojection_px": float(read_bundler(path).reprojection_errors().mean())}


def stage_seconds(scene: SceneLayout) -> dict[str, float]:
    """Seconds of each photo stage the run ran (its summary's), NaN for those it did not."""
    files = {"poses": scene.poses["summary"], "masks": scene.masks / "summary.json",
             "geometry": scene.geometry["summary"], "uv": scene.geometry["uv_summary"]}
    return {f"{stage}_seconds": float(json.loads(path.read_text())["seconds"]) if path.is_file() else float("nan")
            for stage, path in files.items()}


def prepare(name: str, capture: RealCapture) -> Path:
    """The captures folder the run reads: the capture's own, or for a photos-only one a copy of its photos with a
    scene.yaml (what a user brings) in the study folder."""
    if not capture.photos_only:
        return capture.folder.parent
    folder = WORK / "captures" / name
    if not (folder / "images").is_dir():
        shutil.copytree(capture.folder / "images", folder / "images")
    options = {"prior": capture.prior, "object": name}
    if capture.held_out_every:
        stems = sorted(p.stem for p in (folder / "images").iterdir() if p.is_file())
        options["held_out"] = stems[capture.held_out_every // 2::capture.held_out_every]
    (folder / "scene.yaml").write_text(yaml.safe_dump(options))
    return folder.parent


def run_workflow(config: dict, cores: int) -> tuple[float, str]:
    """Seconds of one Snakemake run of `config` from an empty results folder, and where it stopped ("" when it
    finished); Snakemake's log beside it."""
    shutil.rmtree(WORK / "results", ignore_errors=True)
    path = WORK / "config.yaml"
    path.write_text(yaml.safe_dump(config))
    start = time.perf_counter()
    with open(WORK / "snakemake.log", "w") as log:
        done = subprocess.run([sys.executable, "-m", "snakemake", "--cores", str(cores), "--configfile", str(path)],
                              cwd=ROOT, stdout=log, stderr=subprocess.STDOUT)
    stopped = ""
    if done.returncode:
        text = (WORK / "snakemake.log").read_text()
        stopped = next((line.split("Error in rule ")[1].rstrip(":") for line in text.splitlines()
                        if "Error in rule " in line), "snakemake failed")
    return time.perf_counter() - start, stopped


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--capture", default="skull_photos", choices=("skull_photos", "saharov32"))
    parser.add_argument("--captures", type=Path, default=ROOT.parent / "shared" / "captures",
                        help="the shared captures folder (saharov32 is read from it)")
    parser.add_argument("--cores", type=int, default=2)
    parser.add_argument("--samples", type=int, default=2, help="posterior samples per method")
    parser.add_argument("--variant", default="defaults", choices=tuple(VARIANTS),
                        help="the defaults a user gets, or a named change of them")
    args = parser.parse_args()
    name, capture = args.capture, captures(args.captures)[args.capture]
    WORK.mkdir(parents=True, exist_ok=True)
    config = {"scenes": [name], "captures_dir": str(prepare(name, capture)), "results_dir": str(WORK / "results"),
              "methods": [m for m in METHODS if m != "init"], "samples": args.samples, **VARIANTS[args.variant]}
    seconds, stopped = run_workflow(config, args.cores)
    results = WORK / "results"
    scene = SceneLayout(results / name)
    ious = mask_scores(scene.masks, capture.folder / capture.checked)
    masks_summary = scene.masks / "summary.json"
    flagged = json.loads(masks_summary.read_text()).get("unreliable", []) if masks_summary.is_file() else []
    poses = json.loads((capture.folder / capture.poses_summary).read_text() if capture.poses_summary
                       else scene.poses["summary"].read_text())
    psnr = held_out_psnr(results / "eval" / "summary.csv")
    size = read_mask(next(scene.masks.glob("*.png"))).shape
    flags = [v in flagged for v in ious]
    below_09 = [iou < 0.9 for iou in ious.values()]
    row = {"capture": name, "variant": args.variant, "views": poses["images"], "size": f"{size[1]}x{size[0]}",
           "registered": poses["registered"] / poses["images"], "reprojection_px": poses["mean_reprojection_error_px"],
           **reference_errors(capture, scene.poses["cameras"]),
           "mask_iou": float(np.mean(list(ious.values()))), "mask_iou_min": min(ious.values()),
           "masks_flagged": len(flagged), **flag_counts(list(ious.values()), flags),
           "masks_below_09": sum(below_09), "flagged_below_09": sum(f and b for f, b in zip(flags, below_09)),
           **stage_seconds(scene), **{f"{m}_view_psnr": psnr.get(m, float("nan")) for m in METHODS},
           "seconds": seconds, "stopped": stopped}
    append_row(CSV, row, COLUMNS, settings_hash(config))
    worst = sorted(ious, key=ious.get)[:3]
    print(yaml.safe_dump({**row, "worst_masks": {v: round(ious[v], 3) for v in worst}, "flagged": flagged},
                         sort_keys=False))


if __name__ == "__main__":
    main()
