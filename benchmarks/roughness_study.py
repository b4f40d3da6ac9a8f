"""Env-map diversity of `dps` samples against material roughness (the paper's Fig. 9), over repeats.

Renders one object at each roughness under the same natural light (dpi.studies.roughness.SweepConfig); each
repeat has its own capture noise, init and sample seed stream and draws `--samples` (default 6) dps samples
with the shipped outdoor prior (dps at its defaults, `--steps` respaced steps). Rows (roughness, metallic,
repeat, samples, env_sigma2_sample) go to benchmarks/results/roughness_study.csv, the plot beside it; it prints
mean +- std per roughness.

    .venv/bin/python benchmarks/roughness_study.py [--roughness 0.05 0.2 0.5 0.9] [--repeats 3] [--jobs 2]
"""

from __future__ import annotations

import argparse
import multiprocessing
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, replace
from functools import partial
from pathlib import Path

import numpy as np

from dpi.studies.engine import settings_hash, write_rows
from dpi.studies.roughness import SweepConfig, roughness_point

ROOT = Path(__file__).resolve().parent.parent
CSV = ROOT / "benchmarks" / "results" / "roughness_study.csv"
COLUMNS = ("roughness", "metallic", "repeat", "samples", "env_sigma2_sample")


def point(task: tuple[float, int], folder: str, settings: SweepConfig) -> dict[str, float]:
    """One (roughness, repeat) of the study (a pool task; one render thread)."""
    from dpi.prior.sample import load_default_prior

    roughness, repeat = task
    return roughness_point(roughness, repeat, load_default_prior("outdoor"), folder, settings, threads=1)


def plot(rows: list[dict[str, float]], path: Path) -> None:
    """sigma2_sample per roughness: each repeat as a dot, the mean as a line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4.5, 3.2), dpi=120)
    xs = sorted({r["roughness"] for r in rows})
    means = [np.mean([r["env_sigma2_sample"] for r in rows if r["roughness"] == x]) for x in xs]
    ax.plot(xs, means, "-", color="C0", label="mean")
    ax.plot([r["roughness"] for r in rows], [r["env_sigma2_sample"] for r in rows], "o", color="C0", alpha=0.5,
            label="repeat")
    ax.set_xlabel("roughness")
    ax.set_ylabel("env $\\sigma^2_{sample}$")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--roughness", type=float, nargs="+", default=[0.05, 0.2, 0.5, 0.9])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--samples", type=int, default=SweepConfig.samples)
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--jobs", type=int, default=2, help="(roughness, repeat) points run side by side")
    parser.add_argument("--out", type=Path, default=CSV)
    args = parser.parse_args()

    defaults = SweepConfig()
    settings = replace(defaults, samples=args.samples, dps=replace(defaults.dps, steps=args.steps))
    tasks = [(r, k) for r in args.roughness for k in range(args.repeats)]
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp, \
            ProcessPoolExecutor(args.jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
        rows = list(pool.map(partial(point, folder=tmp, settings=settings), tasks))
    write_rows(args.out, [{k: row[k] for k in COLUMNS} for row in rows], settings_hash(asdict(settings)))
    plot(rows, args.out.with_suffix(".png"))
    print(f"{args.repeats} repeats x {settings.samples} dps samples per roughness, {args.steps} steps, "
          f"{time.perf_counter() - start:.0f} s in all")
    print(f"{'roughness':>9} {'metallic':>8} {'env sigma2_sample (mean +- std over repeats)':>46}")
    for r in args.roughness:
        values = np.array([row["env_sigma2_sample"] for row in rows if row["roughness"] == r])
        metallic = next(row["metallic"] for row in rows if row["roughness"] == r)
        print(f"{r:>9.3f} {metallic:>8.1f} {values.mean():>37.5f} +- {values.std():.5f}")


if __name__ == "__main__":
    main()
