"""The lens study's table."""

from __future__ import annotations

from pathlib import Path

from table_format import ALBEDO, ENV, VIEW, Metric, grouped_table, latest, read_rows

HERE = Path("benchmarks") / "lens"
"""the study's folder, relative to a checkout's root"""


def lens(root: Path) -> str:
    """Lens study: a capture through a barrel lens, undistorted by dpi or its distortion ignored, against its
    pinhole twin; the view PSNR also paired with the twin's of the same seed."""
    rows = latest(read_rows(root / HERE / "lens.csv", ("variant",)), ("variant", "seed"))
    twin = {r["seed"]: r["novel_psnr"] for r in rows if r["variant"] == "pinhole"}
    for row in rows:
        row["paired"] = row["novel_psnr"] - twin[row["seed"]] if row["seed"] in twin else None
    metrics = (VIEW, Metric("view PSNR - pinhole's [dB]", "paired", "+.2f"), ENV, ALBEDO)
    order = ("pinhole", "undistorted", "ignored")
    return grouped_table(rows, ("variant",), metrics, order=lambda k: order.index(k[0]) if k[0] in order else 9)


TABLES = {"lens": lens}
"""the study's tables by the name their markers use"""
