"""Does a posterior contract as the views grow? One scene whose true light is a sample of the outdoor prior (so the
prior is right by construction), a rough blob seen all around from 4, 16 and 64 training views, `dps` drawn through
the workflow at the defaults a user gets; a row per view count: the samples' light (env PSNR a sample and of their
mean map, log error at 2 and 8 rows), their spread and calibration, the training fit, seconds a sample.

    .venv/bin/python benchmarks/contraction/contraction.py [--work DIR] [--views 4 16 64] [--samples 3]
        [--out benchmarks/contraction/contraction.csv]

A posterior that the views tighten shows errors and spread falling with the views and a calibration that stays
near 1 (the truth as likely as one more sample). The CSV's rows are replaced.
"""

from __future__ import annotations

import argparse
from pathlib import Path


from dpi.io.exr import write_exr
from dpi.io.layout import INIT
from dpi.prior.sample import draw_samples, load_default_prior
from dpi.studies.engine import CHECKOUT, run_workflow, summary_rows, write_rows
from dpi.studies.scenes import AMBIGUOUS

HERE = Path(__file__).resolve().parent
FAMILY = "outdoor"
TRUTH_SEED = 7
"""the prior sample that is the scene's light (drawn with this seed, 100 steps)"""
HELD_OUT_EVERY = 5
"""one view in five is held out: 4 / 16 / 64 training views of 5 / 20 / 80"""
SCENE = {**AMBIGUOUS, "shape": "blob", "seed": 0, "arc_deg": 360.0, "held_out_every": HELD_OUT_EVERY,
         "prior": FAMILY}
"""the rough dielectric of the studies' ambiguous group, seen all around"""
COLUMNS = ("samples", "novel_psnr", "env_psnr", "env_mean_psnr", "env_balance_2", "env_balance_8",
           "env_mean_balance_2", "env_mean_balance_8", "env_log_std", "env_calibration", "train_fit_over_truth",
           "sample_seconds")
"""the evaluation summary's columns a row keeps (dpi.evaluation.summary)"""


def truth_map(path: Path) -> Path:
    """The scene's light: one sample of the outdoor prior at its median-1 radiance, written once."""
    if not path.is_file():
        prior = load_default_prior(FAMILY)
        x = draw_samples(prior, 1, steps=100, seed=TRUTH_SEED)[0]
        path.parent.mkdir(parents=True, exist_ok=True)
        write_exr(path, prior.encoding.to_radiance(x).permute(1, 2, 0).numpy())
    return path


def scene_name(views: int) -> str:
    return f"contraction_{views}"


def workflow(work: Path, views: list[int], samples: int) -> Path:
    """Run the workflow on one synthetic scene per view count in `work`; its results folder."""
    truth = truth_map(work / "truth.exr")
    synthetic = {scene_name(n): {**SCENE, "views": n * HELD_OUT_EVERY // (HELD_OUT_EVERY - 1),
                                 "environment": str(truth)} for n in views}
    return run_workflow(work, {"scenes": list(synthetic), "synthetic": synthetic, "methods": ["dps"],
                               "samples": samples})


def view_rows(results: Path, views: list[int]) -> list[dict]:
    """A row per view count and method (the init, dps) from the evaluation summary."""
    rows = summary_rows(results, COLUMNS)
    return [{"views": n, "method": method, **rows[(scene_name(n), method)]} for n in views for method in (INIT, "dps")]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--work", type=Path, default=CHECKOUT / "results" / "benchmarks" / "contraction")
    parser.add_argument("--views", type=int, nargs="+", default=[4, 16, 64], help="training views of each capture")
    parser.add_argument("--samples", type=int, default=3, help="dps samples of each capture")
    parser.add_argument("--out", type=Path, default=HERE / "contraction.csv")
    args = parser.parse_args()
    rows = view_rows(workflow(args.work, args.views, args.samples), args.views)
    write_rows(args.out, rows, settings="defaults")
    for row in rows:
        print(" ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()))


if __name__ == "__main__":
    main()
