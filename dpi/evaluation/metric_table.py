"""summary.csv as an HTML table: missing cells greyed with their reason, the best value per scene marked.

The CSVs keep numeric columns numeric: a metric that could not be computed is an empty cell, and its reason
is one entry of the row's `notes` column (`column: reason; ...`); `read_summary` folds the reasons back."""

from __future__ import annotations

import csv
import math
from html import escape
from pathlib import Path
from typing import Any

MISSING = "missing"
HIGHER_BETTER = {"psnr", "ssim", "naturalness"}
LOWER_BETTER = {"mse", "lpips", "fid", "niqe", "sigma2", "balance", "seam"}
UNRANKED = ("sigma2_sample",)
"""spread across posterior samples: a property of the posterior, neither more nor less is better"""
STD_SUFFIX = "_std"
NOTES = "notes"
"""the column that holds the reasons of a row's empty (missing) cells"""
NOTE_SEPARATOR = "; "


def split_missing(row: dict[str, Any]) -> dict[str, Any]:
    """A row as written to CSV: each `missing: <reason>` cell empty, its reason in the `notes` column."""
    reasons = {k: missing_reason(v) for k, v in row.items() if isinstance(v, str) and missing_reason(v)}
    cells = {k: ("" if k in reasons else v) for k, v in row.items()}
    return {**cells, NOTES: NOTE_SEPARATOR.join(f"{k}: {why}" for k, why in reasons.items())}


def join_missing(row: dict[str, str]) -> dict[str, str]:
    """A CSV row read back: each empty cell named in `notes` is `missing: <reason>` again (split_missing undone)."""
    notes = row.pop(NOTES, "") or ""
    for entry in filter(None, notes.split(NOTE_SEPARATOR)):
        column, _, why = entry.partition(": ")
        if column in row and not row[column]:
            row[column] = f"{MISSING}: {why}"
    return row


def read_summary(path: str | Path) -> list[dict[str, str]]:
    """Rows of summary.csv as column -> cell text, a missing metric as `missing: <reason>`."""
    with open(path, newline="") as f:
        return [join_missing(row) for row in csv.DictReader(f)]


def number(cell: str | None) -> float | None:
    """The value of a numeric cell, None for empty, missing or text cells."""
    try:
        value = float(cell)
    except (TypeError, ValueError):
        return None
    return None if math.isnan(value) else value


def missing_reason(cell: str | None) -> str | None:
    """The reason of a `missing: <reason>` cell, None for other cells."""
    if cell is None or not cell.startswith(MISSING):
        return None
    return cell[len(MISSING):].lstrip(": ") or "no reason recorded"


def direction(column: str) -> int:
    """+1 when higher values of a column are better, -1 when lower ones are, 0 when it is not ranked."""
    if any(column.endswith(name) for name in UNRANKED):
        return 0
    words = set(column.split("_"))
    return 1 if words & HIGHER_BETTER else -1 if words & LOWER_BETTER else 0


def shown_columns(rows: list[dict[str, str]]) -> list[str]:
    """Columns of the table: every CSV column, except `x_std`, which is shown in x's cell."""
    columns = list(rows[0]) if rows else []
    return [c for c in columns if not (c.endswith(STD_SUFFIX) and c[: -len(STD_SUFFIX)] in columns)]


def best_cells(rows: list[dict[str, str]], columns: list[str]) -> set[tuple[int, str]]:
    """(row index, column) of the best value per scene and ranked column, among at least two numbers."""
    best = set()
    for scene in dict.fromkeys(r["scene"] for r in rows):
        indices = [i for i, r in enumerate(rows) if r["scene"] == scene]
        for column in columns:
            sign = direction(column)
            values = {i: number(rows[i].get(column)) for i in indices}
            values = {i: sign * v for i, v in values.items() if v is not None}
            if sign and len(values) > 1:
                top = max(values.values())
                best |= {(i, column) for i, v in values.items() if v == top}
    return best


def _header(column: str) -> str:
    """Header cell with an arrow telling which way is better."""
    sign = direction(column)
    if sign == 0:
        return f"<th>{escape(column)}</th>"
    arrow, word = ("&uarr;", "higher") if sign > 0 else ("&darr;", "lower")
    return f'<th title="{word} is better">{escape(column)} {arrow}</th>'


def _cell(row: dict[str, str], column: str, best: bool) -> str:
    """One table cell: a number (with its std), a greyed missing value with its reason, or text."""
    text = row.get(column) or ""
    reason = missing_reason(text)
    if reason is not None:
        return f'<td class="missing" title="{escape(reason)}">missing</td>'
    value = number(text)
    if value is None:
        return f"<td>{escape(text)}</td>"
    shown = f"{value:.4g}"
    std = number(row.get(column + STD_SUFFIX))
    if std is not None:
        shown += f' <span class="std">&plusmn; {std:.2g}</span>'
    return f'<td class="best"><strong>{shown}</strong></td>' if best else f"<td>{shown}</td>"


def metric_table(rows: list[dict[str, str]]) -> str:
    """HTML table of summary rows; a scene's first row starts a new group."""
    columns = shown_columns(rows)
    best = best_cells(rows, columns)
    header = "".join(_header(c) for c in columns)
    lines = ['<table class="metrics">', f"<thead><tr>{header}</tr></thead>", "<tbody>"]
    for i, row in enumerate(rows):
        first = i == 0 or row["scene"] != rows[i - 1]["scene"]
        cells = "".join(_cell(row, c, (i, c) in best) for c in columns)
        lines.append(f'<tr class="scene-start">{cells}</tr>' if first else f"<tr>{cells}</tr>")
    return "\n".join(lines + ["</tbody>", "</table>"])
