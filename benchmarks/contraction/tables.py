"""The contraction study's table."""

from __future__ import annotations

from pathlib import Path

from table_format import Metric, grouped_table, read_rows

HERE = Path("benchmarks") / "contraction"
"""the study's folder, relative to a checkout's root"""


def contraction(root: Path) -> str:
    """The contraction study (benchmarks/contraction): the samples' light, spread and calibration per view count."""
    rows = read_rows(root / HERE / "contraction.csv")
    metrics = (Metric("samples", "samples", ".0f", spread=False),
               Metric("env PSNR [dB]", "env_psnr", ".2f", +1, spread=False),
               Metric("mean map: env PSNR [dB]", "env_mean_psnr", ".2f", +1, spread=False),
               Metric("log error at 2 rows", "env_balance_2", ".2f", -1, spread=False),
               Metric("at 8 rows", "env_balance_8", ".2f", -1, spread=False),
               Metric("spread (log std)", "env_log_std", ".3f", spread=False),
               Metric("calibration (1: ideal)", "env_calibration", ".2f", spread=False),
               Metric("training fit / truth's", "train_fit_over_truth", ".2f", spread=False),
               Metric("s/sample", "sample_seconds", ".1f", spread=False))
    return grouped_table(rows, ("views", "method"), metrics)


TABLES = {"contraction": contraction}
"""the study's tables by the name their markers use"""
