"""Pareto front of study rows: which settings no other setting beats in every objective."""

from __future__ import annotations


def pareto_front(rows: list[dict[str, float]], minimize: tuple[str, ...], maximize: tuple[str, ...]) -> list[bool]:
    """Per row, whether no other row is at least as good in every objective and better in one."""
    def dominates(a: dict[str, float], b: dict[str, float]) -> bool:
        no_worse = all(a[k] <= b[k] for k in minimize) and all(a[k] >= b[k] for k in maximize)
        better = any(a[k] < b[k] for k in minimize) or any(a[k] > b[k] for k in maximize)
        return no_worse and better

    return [not any(dominates(other, row) for other in rows if other is not row) for row in rows]
