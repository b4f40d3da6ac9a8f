"""Settings dataclasses from config dicts: one strict constructor for every stage's settings."""

from __future__ import annotations

from dataclasses import fields
from typing import Any, TypeVar

T = TypeVar("T")


def settings_from_dict(cls: type[T], values: dict[str, Any] | None) -> T:
    """A settings dataclass from a (partial) dict; unknown keys are an error naming the valid ones."""
    values = dict(values or {})
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"unknown {cls.__name__} settings {unknown}; valid: {', '.join(sorted(known))}")
    return cls(**values)
