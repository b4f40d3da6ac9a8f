"""The tables' format: the metric columns, the grouped `mean ± std` table with the best per group bold, and the
order of methods. Every study's `tables.py` builds its tables from these (benchmarks/doc_tables.py writes them)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from dpi.io.layout import INIT
from dpi.solve.methods import METHODS
from dpi.studies.engine import latest, read_rows

__all__ = ["ALBEDO", "BY_METHOD", "ENV", "FIT", "SECONDS", "VIEW", "Metric", "Row", "grouped_table", "latest",
           "markdown", "method_order", "read_rows", "stats"]

METHOD_ORDER = (INIT, *METHODS)
"""rows of a method table: the init, then the methods in their registry's order"""


Row = dict[str, Any]


@dataclass(frozen=True)
class Metric:
    """One numeric column of a table: its header, the CSV column, the format, and which way is better."""

    header: str
    column: str
    fmt: str
    better: int = 0
    """+1: higher is better, -1: lower, 0: not ranked (the best per group is bold)"""
    spread: bool = True
    """show `mean ± std` (population std over the group's rows), else the mean only"""


def stats(values: Iterable[Any]) -> tuple[float, float] | None:
    """Mean and population std of the finite numbers among `values`; None when there are none."""
    numbers = [v for v in values if isinstance(v, float) and math.isfinite(v)]
    if not numbers:
        return None
    mean = sum(numbers) / len(numbers)
    return mean, math.sqrt(sum((v - mean) ** 2 for v in numbers) / len(numbers))


def markdown(header: list[str], body: list[list[str]]) -> str:
    """A GitHub markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(cells) + " |" for cells in body])


def grouped_table(rows: list[Row], keys: tuple[str, ...], metrics: tuple[Metric, ...], rank_by: str | None = None,
                  order: Callable[[tuple], Any] | None = None) -> str:
    """Mean (± std) of each metric per distinct value of `keys`, with the row count `n`; within each value of
    `rank_by` (one of the keys, or the whole table) the best mean of a ranked metric is bold."""
    groups: dict[tuple, list[Row]] = {}
    for row in rows:
        groups.setdefault(tuple(row[k] for k in keys), []).append(row)
    ordered = sorted(groups, key=order) if order else list(groups)
    means = {g: {m.column: stats(r[m.column] for r in groups[g]) for m in metrics} for g in ordered}
    best: set[tuple[tuple, str]] = set()
    for m in (m for m in metrics if m.better):
        for part in dict.fromkeys(g[keys.index(rank_by)] if rank_by else None for g in ordered):
            members = [g for g in ordered if rank_by is None or g[keys.index(rank_by)] == part]
            scored = {g: m.better * means[g][m.column][0] for g in members if means[g][m.column]}
            if len(scored) > 1:
                top = max(scored.values())
                best |= {(g, m.column) for g, v in scored.items() if v == top}
    body = []
    for g in ordered:
        cells = [_text(v) for v in g] + [str(len(groups[g]))]
        for m in metrics:
            s = means[g][m.column]
            cell = "-" if s is None else f"{s[0]:{m.fmt}}"
            cell = f"**{cell}**" if (g, m.column) in best else cell
            if s is not None and m.spread and len(groups[g]) > 1:
                cell += f" ± {s[1]:{m.fmt.lstrip('+')}}"
            cells.append(cell)
        body.append(cells)
    return markdown([*keys, "n", *(m.header for m in metrics)], body)


def _text(value: Any) -> str:
    """A key cell: a number as short as it reads (0.05, 128), text as it is."""
    if isinstance(value, float):
        return f"{value:g}"
    return "" if value is None else str(value)


def method_order(key: tuple, method_at: int = 1) -> tuple:
    """Sort key: the keys before the method as they are, then the methods in METHOD_ORDER, then the rest."""
    method = key[method_at]
    rank = METHOD_ORDER.index(method) if method in METHOD_ORDER else len(METHOD_ORDER)
    return (*key[:method_at], rank, *(str(k) for k in key[method_at + 1:]))


BY_METHOD = ("group", "method", "sampler")
"""the rows a study table shows: one per group, method and dps sampler"""


VIEW = Metric("view PSNR [dB]", "novel_psnr", ".2f", +1)


ENV = Metric("env PSNR [dB]", "env_psnr", ".2f", +1)


ALBEDO = Metric("albedo MSE", "albedo_mse", ".4f", -1, spread=False)


SECONDS = Metric("s/sample", "seconds", ".1f", spread=False)


FIT = Metric("training fit / truth's", "train_fit_over_truth", ".2f")
"""a sample's training-view fit over the truth's (dpi.evaluation.train_fit): 1 is a posterior sample's"""
