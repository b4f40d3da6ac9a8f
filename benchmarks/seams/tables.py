"""The seams' table."""

from __future__ import annotations

import math
from pathlib import Path

from table_format import Metric, grouped_table, method_order, read_rows

HERE = Path("benchmarks") / "seams"
"""the study's folder, relative to a checkout's root"""


def seams(root: Path) -> str:
    """The albedo's seam ratio (benchmarks/seams/seams.py) per capture, scene and method: mean and worst over seeds, with
    the given mesh's faces, the atlas's and its texture size."""
    rows = read_rows(root / HERE / "seams.csv", ("capture", "scene", "method"))
    worst: dict[tuple, float] = {}
    for row in rows:
        key = (row["capture"], row["scene"], row["method"])
        worst[key] = max(worst.get(key, -math.inf), row["albedo_seam"])
    rows = [{**row, "worst": worst[(row["capture"], row["scene"], row["method"])]} for row in rows]
    shown = (Metric("albedo seam ratio", "albedo_seam", ".2f", -1), Metric("worst", "worst", ".2f", 0, spread=False),
             *(Metric(header, column, ".0f", 0, spread=False) for header, column in
               (("given faces", "given_faces"), ("atlas faces", "faces"), ("texture size", "texture_size"))))
    return grouped_table(rows, ("capture", "scene", "method"), shown, rank_by="scene", order=method_order)


TABLES = {"seams": seams}
"""the study's tables by the name their markers use"""
