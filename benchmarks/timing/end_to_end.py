"""Wall time of the whole default workflow on a real-size synthetic capture, per quality preset.

Captures, made once (not timed) into results/benchmarks/end_to_end/captures/: the demo object
rendered at 60 views of 512 x 512 px with cameras, masks and mesh (every 10th view held out), and 40
JPEG photos of 1600 x 1200 px of a textured blob in front of a textured backdrop with nothing else
(preprocessing derives poses, masks, surface and UVs). Each preset then runs the whole workflow on
a capture from scratch: preprocessing where needed, init, the configured methods' samples,
evaluation, figures and report (`snakemake --cores N`); the preset's working resolution decides the
size the inverse stages work at.
Rows (capture, views, size, preset, seconds) go to benchmarks/timing/end_to_end.csv.

    .venv/bin/python benchmarks/timing/end_to_end.py [--presets draft default] [--cores 2]
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import time
from pathlib import Path

import yaml

from dpi.io.layout import SYNTH_MARKER
from dpi.studies.engine import CHECKOUT as ROOT
from dpi.studies.engine import append_row, settings_hash, work_dir

WORK = work_dir("end_to_end")
CSV = Path(__file__).resolve().parent / "end_to_end.csv"
COLUMNS = ("capture", "views", "size", "preset", "seconds")
CAPTURES = {
    "synthetic_60x512": {"views": 60, "held_out_every": 10, "width": 512, "height": 512, "spp": 64},
    "photos_40x1600_jpg": {"views": 40, "held_out_every": 8, "width": 1600, "height": 1200, "spp": 8,
                           "texture_size": 256, "camera_distance": 6.0, "elevations_deg": [15.0, 30.0],
                           "albedo_detail": 0.6, "background": "textured", "image_format": "jpg",
                           "photos_only": True},
}


def run_preset(capture: str, synth: dict, preset: str, cores: int) -> float:
    """Seconds of one workflow run of `preset` on the capture (its results folder emptied first)."""
    results = WORK / preset / "results"
    shutil.rmtree(results, ignore_errors=True)
    config = {"captures_dir": str(WORK / "captures"), "results_dir": str(results), "scenes": [capture],
              "synthetic": {capture: synth}, "preset": preset}
    path = WORK / preset / "config.yaml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(config))
    # the capture is rendered once, untimed: only the workflow after it counts
    marker = WORK / "captures" / capture / SYNTH_MARKER
    snakemake, options = [sys.executable, "-m", "snakemake"], ["--cores", str(cores), "--configfile", str(path)]
    with open(WORK / preset / "snakemake.log", "w") as log:  # Snakemake's own log; each job's is under results/
        subprocess.run([*snakemake, str(marker), *options], cwd=ROOT, check=True, stdout=log, stderr=subprocess.STDOUT)
        start = time.perf_counter()
        subprocess.run([*snakemake, *options], cwd=ROOT, check=True, stdout=log, stderr=subprocess.STDOUT)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--presets", nargs="+", default=["draft", "default"])
    parser.add_argument("--captures", nargs="+", default=list(CAPTURES), choices=list(CAPTURES))
    parser.add_argument("--cores", type=int, default=2)
    args = parser.parse_args()
    for capture in args.captures:
        synth = CAPTURES[capture]
        for preset in args.presets:
            seconds = run_preset(capture, synth, preset, args.cores)
            row = {"capture": capture, "views": synth["views"], "size": f"{synth['width']}x{synth['height']}",
                   "preset": preset, "seconds": round(seconds, 1)}
            append_row(CSV, row, COLUMNS, settings_hash({"synth": synth, "preset": preset, "cores": args.cores}))
            print("  ".join(f"{k} {v}" for k, v in row.items()), flush=True)


if __name__ == "__main__":
    main()
