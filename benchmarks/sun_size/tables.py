"""The written sun's size table."""

from __future__ import annotations

from pathlib import Path

from table_format import ENV, VIEW, Metric, grouped_table, read_rows

HERE = Path("benchmarks") / "sun_size"
"""the study's folder, relative to a checkout's root"""


def sun_size(root: Path) -> str:
    """The written sun's size the training views chose (benchmarks/sun_size/sun_size.py), per scene over its samples."""
    rows = read_rows(root / HERE / "sun_size.csv", ("scene",))
    metrics = (Metric("radius written [deg]", "radius_deg", ".2f", 0),
               Metric("views' loss: chosen / own size", "loss_ratio", ".2f", -1),
               Metric("training fit / truth's", "train_fit_over_truth", ".2f", -1), ENV, VIEW)
    return grouped_table(rows, ("scene",), metrics)


TABLES = {"sun_size": sun_size}
"""the study's tables by the name their markers use"""
