"""The paper's reference capture (the authors' hotdog) through the workflow at the defaults a user gets: a row per
method and a picture of the maps beside the truth's.

    .venv/bin/python benchmarks/hotdog/hotdog.py CAPTURES [--work DIR] [--methods none smoothness dip dps]
        [--samples 2] [--dps-samples 3] [--out benchmarks/hotdog/hotdog.csv] [--figure benchmarks/hotdog/hotdog_envmaps.png]

CAPTURES is the folder `../shared/tools/hotdog/prepare.py` wrote (it holds `hotdog/`); nothing of the capture is
committed (its repository names no licence). The workflow runs in `--work` (a config.yaml there names the capture,
the methods and the sample counts; every other setting is the default), then each method's row is read from its
evaluation summary (results/eval/summary.csv): held-out views, env PSNR a sample and of the samples' mean map, the
mean map's log error at 2 and 8 rows, the calibration, seconds a sample. The CSV's rows are replaced.
"""

from __future__ import annotations

import argparse
from pathlib import Path


from dpi.evaluation.figures import envmap_grid
from dpi.io.layout import INIT, Layout
from dpi.studies.engine import CHECKOUT, run_workflow, summary_rows, write_rows

SCENE = "hotdog"
HERE = Path(__file__).resolve().parent
COLUMNS = ("samples", "novel_psnr", "env_psnr", "env_mean_psnr", "env_balance_2", "env_balance_8",
           "env_mean_balance_2", "env_mean_balance_8", "env_calibration", "train_fit", "sample_seconds")
"""the summary's columns a row keeps (dpi.evaluation.summary)"""


def workflow(captures: Path, work: Path, methods: list[str], samples: int, dps_samples: int) -> Layout:
    """Run the workflow on the capture in `work` (its config written there); the run's layout."""
    config = {"scenes": [SCENE], "captures_dir": str(captures.resolve()), "methods": methods, "samples": samples,
              "method_params": {"dps": {"samples": dps_samples}}}
    return Layout(run_workflow(work, config), captures)


def method_rows(layout: Layout) -> list[dict]:
    """The scene's row per method from the evaluation summary."""
    return [{"method": method, **row} for (scene, method), row in summary_rows(layout.results, COLUMNS).items()
            if scene == SCENE]


def figure(layout: Layout, methods: list[str], path: Path) -> None:
    """The truth's map on top, then the init's and each method's samples (scale-aligned to the truth's)."""
    scene = layout.scene(SCENE)
    rows = [(INIT, [scene.sample_files(INIT)["env"]])]
    for method in methods:
        files = sorted(scene.sample_dir(method, 0).parent.glob("*/envmap.exr"))
        rows.append((method, files))
    envmap_grid(rows, path, reference=layout.capture_dir(SCENE) / "gt" / "envmap.exr")
    from PIL import Image

    with Image.open(path) as image:  # a picture for the docs: three quarters of the size, 64 colours
        small = image.convert("RGB").resize((3 * image.width // 4, 3 * image.height // 4), Image.LANCZOS)
    small.quantize(64).save(path, optimize=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("captures", type=Path, help="the folder prepare.py wrote (holding hotdog/)")
    parser.add_argument("--work", type=Path, default=CHECKOUT / "results" / "benchmarks" / "hotdog")
    parser.add_argument("--methods", nargs="+", default=["none", "smoothness", "dip", "dps"])
    parser.add_argument("--samples", type=int, default=2, help="samples of each baseline")
    parser.add_argument("--dps-samples", type=int, default=3)
    parser.add_argument("--out", type=Path, default=HERE / "hotdog.csv")
    parser.add_argument("--figure", type=Path, default=HERE / "hotdog_envmaps.png")
    args = parser.parse_args()
    if not (args.captures / SCENE / "gt" / "envmap.exr").is_file():
        parser.error(f"{args.captures}: no {SCENE}/gt/envmap.exr; prepare the capture with "
                     "../shared/tools/hotdog/prepare.py (its README)")
    layout = workflow(args.captures, args.work, args.methods, args.samples, args.dps_samples)
    rows = method_rows(layout)
    write_rows(args.out, rows, settings="defaults")
    figure(layout, [m for m in args.methods if m != INIT], args.figure)
    for row in rows:
        print(" ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()))


if __name__ == "__main__":
    main()
