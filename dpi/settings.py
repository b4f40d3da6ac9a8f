"""Settings dataclasses from config dicts: one strict constructor for every stage's settings."""

from __future__ import annotations

import copy
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


def apply_preset(config: dict[str, Any]) -> dict[str, Any]:
    """Fill what `config` leaves unset from its quality preset `config["presets"][config["preset"]]`.

    Nested dicts are filled key by key, so a key the user sets always wins over the preset; no
    `preset` key means no preset. Returns the config (filled in place)."""
    name = config.get("preset")
    if name is None:
        return config
    presets = config.get("presets", {})
    if name not in presets:
        raise ValueError(f"unknown preset {name!r}; config.yaml defines: {', '.join(sorted(presets)) or 'none'}")
    _fill(config, presets[name])
    return config


def _fill(target: dict[str, Any], defaults: dict[str, Any]) -> None:
    """Recursively set the keys of `defaults` that `target` lacks."""
    for key, value in defaults.items():
        if isinstance(value, dict) and isinstance(target.get(key), dict):
            _fill(target[key], value)
        elif key not in target:
            target[key] = copy.deepcopy(value)
