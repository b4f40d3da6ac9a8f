"""The roughness study's table (Fig. 9)."""

from __future__ import annotations

from pathlib import Path

from table_format import Metric, grouped_table, latest, read_rows

HERE = Path("benchmarks") / "roughness"
"""the study's folder, relative to a checkout's root"""


def roughness(root: Path) -> str:
    """Roughness study (Fig. 9): env sigma2_sample of dps samples per roughness, over repeats."""
    rows = latest(read_rows(root / HERE / "roughness.csv"), ("roughness", "repeat"))
    return grouped_table(rows, ("roughness", "metallic"),
                         (Metric("env sigma2_sample", "env_sigma2_sample", ".4f"),), order=lambda k: k)


TABLES = {"roughness": roughness}
"""the study's tables by the name their markers use"""
