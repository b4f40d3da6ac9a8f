"""The resolution study's table."""

from __future__ import annotations

from pathlib import Path

from table_format import ENV, SECONDS, VIEW, Metric, grouped_table, latest, read_rows

HERE = Path("benchmarks") / "resolution"
"""the study's folder, relative to a checkout's root"""


def resolution(root: Path) -> str:
    """Resolution study: dps at each map size, a mirror-like torus and a rough blob."""
    rows = latest(read_rows(root / HERE / "resolution.csv"), ("scene", "env_height", "texture_size", "seed"))
    for row in rows:
        row["env map"] = f"{int(row['env_height'])} x {2 * int(row['env_height'])}"
    metrics = (VIEW, ENV, Metric("relight PSNR-H [dB]", "relight_psnr_h", ".2f", +1), SECONDS)
    return grouped_table(rows, ("group", "env map"), metrics, rank_by="group",
                         order=lambda k: (k[0], int(k[1].split()[0])))


TABLES = {"resolution": resolution}
"""the study's tables by the name their markers use"""
