"""The authors' capture's table."""

from __future__ import annotations

from pathlib import Path

from table_format import ENV, VIEW, Metric, grouped_table, method_order, read_rows

HERE = Path("benchmarks") / "hotdog"
"""the study's folder, relative to a checkout's root"""


def hotdog(root: Path) -> str:
    """The authors' capture at the defaults, a row per method (benchmarks/hotdog/hotdog.py)."""
    rows = read_rows(root / HERE / "hotdog.csv", ("method",))
    metrics = (Metric("samples", "samples", ".0f"), VIEW, ENV, Metric("mean map env PSNR [dB]", "env_mean_psnr", ".2f", +1),
               Metric("mean map log error, 2 rows", "env_mean_balance_2", ".2f", -1),
               Metric("at 8 rows", "env_mean_balance_8", ".2f", -1), Metric("calibration", "env_calibration", ".2f"),
               Metric("s/sample", "sample_seconds", ".1f"))
    return grouped_table(rows, ("method",), metrics, order=lambda key: method_order(key, 0))


TABLES = {"hotdog": hotdog}
"""the study's tables by the name their markers use"""
