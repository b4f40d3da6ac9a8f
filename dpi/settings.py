"""Settings dataclasses from config dicts: one strict constructor for every stage's settings.

`settings_from_dict` rejects unknown keys, values of the wrong type (from the dataclass's
annotations) or non-finite numbers, and numbers outside `FIELD_BOUNDS`. The bounds go by field
name, so every settings dataclass that follows the naming conventions (`steps`, `iterations`,
`views_per_step`, `lr_*`, ...) is checked without declaring anything, new fields included.
Errors are `SettingsError`s that carry the offending key, so a config reader can put the key's
full path in front (`method_params.dps.steps: must be >= 1, got -5`).
"""

from __future__ import annotations

import copy
import difflib
import math
import types
from collections.abc import Iterable
from dataclasses import MISSING, dataclass, fields
from fnmatch import fnmatchcase
from typing import Any, TypeVar, Union, get_args, get_origin, get_type_hints

T = TypeVar("T")


class SettingsError(ValueError):
    """A settings key or value is unusable; `key` names it and the message reads `key: problem`."""

    def __init__(self, key: str, problem: str):
        super().__init__(f"{key}: {problem}")
        self.key = key
        self.problem = problem

    def __reduce__(self) -> tuple:
        """Pickle by (key, problem), so the error crosses process pools intact."""
        return type(self), (self.key, self.problem)


@dataclass(frozen=True)
class Bound:
    """The valid range of a numeric setting: low (exclusive when `strict`) and high, both optional."""

    low: float | None = None
    high: float | None = None
    strict: bool = False

    def problem(self, value: float) -> str | None:
        """Why `value` is outside the range, or None."""
        if self.low is not None and (value <= self.low if self.strict else value < self.low):
            return f"must be {'>' if self.strict else '>='} {self.low:g}, got {value!r}"
        if self.high is not None and value > self.high:
            return f"must be <= {self.high:g}, got {value!r}"
        return None


FIELD_BOUNDS: dict[str, Bound] = {
    "steps": Bound(1),
    "*views_per_step": Bound(1),
    "*iterations": Bound(0),
    "lr_*": Bound(0, strict=True),
    "spp": Bound(1),
    "max_depth": Bound(1),
    "views": Bound(1),
    "width": Bound(1),
    "height": Bound(1),
    "rho_switch": Bound(0, 1),
    "t_min": Bound(0, 1),
    "t_max": Bound(0, 1),
    "*_fraction": Bound(0, 1),
    "rho_*": Bound(0),
    "*_ratio": Bound(0),
    "guidance_bound": Bound(0, strict=True),
    "radiance_scale": Bound(0, strict=True),
    "*channels": Bound(1),
    "depth": Bound(1),
    "strip_frames": Bound(1),
    "start_noise": Bound(0),
    "count": Bound(1),
    "data_height": Bound(1),
    "batch_size": Bound(1),
    "threads": Bound(1),
    "passes": Bound(1),
    "ground_seed": Bound(-1, 1),
    "ground_grow": Bound(-1, 1),
    "ground_fit": Bound(0, 1),
    "ground_min_pixels": Bound(0),
    "photo_size": Bound(16),
    "max_incidence_deg": Bound(0, 90),
    "fallback_window": Bound(0),
    "clip_fraction": Bound(0, 1),
    "lr": Bound(0, strict=True),
    "share": Bound(0, 1, strict=True),
    "min_share": Bound(0, 1),
    "radius_deg": Bound(0, 90, strict=True),
    "min_roughness": Bound(0, 1),
    "prior_weight": Bound(0),
    "noise_mix": Bound(0, 1),
    "material_start": Bound(0, 1),
    "prox_weight": Bound(0),
    "inner_steps": Bound(1),
    "*map_solve": Bound(0),
    "perturb": Bound(0),
    "perturb_height": Bound(1),
    "retry_below": Bound(0, 1),
    "retry_gain": Bound(0, 1),
}
"""valid ranges of numeric settings by field-name pattern (fnmatch); the first matching pattern applies"""


def settings_from_dict(cls: type[T], values: dict[str, Any] | None) -> T:
    """A settings dataclass from a (partial) dict; unknown keys, wrong types and out-of-range values are errors."""
    values = dict(values or {})
    check_keys(values, [f.name for f in fields(cls)], f"{cls.__name__} setting")
    check_values(cls, values)
    return cls(**values)


def field_default(cls: type, name: str) -> Any:
    """The default of a dataclass field (a factory's value), e.g. for a command-line option's default."""
    field = next(f for f in fields(cls) if f.name == name)
    return field.default_factory() if field.default is MISSING else field.default


def check_keys(values: Iterable[Any], known: Iterable[str], what: str) -> None:
    """Fail on the first of `values` (keys, names) not in `known`, suggesting the closest valid one;
    `what` names one of them in the message ("DPSConfig setting", "method")."""
    known = sorted(known)
    unknown = sorted(str(k) for k in values if k not in known)
    if unknown:
        close = difflib.get_close_matches(unknown[0], known, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise SettingsError(unknown[0], f"unknown {what}{hint} (valid: {', '.join(known)})")


def check_values(cls: type, values: dict[str, Any]) -> None:
    """Fail on the first value of the wrong type (by `cls`'s annotations), non-finite, or outside FIELD_BOUNDS."""
    try:
        hints = get_type_hints(cls)
    except NameError:  # an annotation names a type only imported for type checkers: check ranges only
        hints = {}
    for key, value in values.items():
        problem = (type_problem(value, hints[key]) if key in hints else None) or bound_problem(key, value)
        if problem:
            raise SettingsError(key, problem)


def type_problem(value: Any, hint: Any) -> str | None:
    """Why `value` does not fit the annotation `hint` (or is a non-finite number), or None."""
    if not _fits(value, hint):
        return f"must be {_describe(hint)}, got {value!r}"
    if isinstance(value, float) and not math.isfinite(value):
        return f"must be a finite number, got {value!r}"
    return None


def bound_problem(key: str, value: Any) -> str | None:
    """Why a numeric `value` of setting `key` is outside its FIELD_BOUNDS range, or None."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    bound = next((b for pattern, b in FIELD_BOUNDS.items() if fnmatchcase(key, pattern)), None)
    return bound.problem(value) if bound else None


def _fits(value: Any, hint: Any) -> bool:
    """Whether `value` is of the annotated type; annotations other than plain types, unions and lists pass."""
    origin, args = get_origin(hint), get_args(hint)
    if origin in (Union, types.UnionType):
        return any(_fits(value, a) for a in args)
    if hint is type(None):
        return value is None
    if hint is bool:
        return isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if hint is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if hint is str:
        return isinstance(value, str)
    if origin in (tuple, list):
        return isinstance(value, (tuple, list)) and (not args or all(_fits(v, args[0]) for v in value))
    return True


def _describe(hint: Any) -> str:
    """An annotation in words, for error messages ("an integer", "a number or null", ...)."""
    origin, args = get_origin(hint), get_args(hint)
    if origin in (Union, types.UnionType):
        return " or ".join(_describe(a) for a in args)
    if origin in (tuple, list):
        return f"a list of {_describe(args[0]) if args else 'values'}"
    names = {type(None): "null", bool: "true or false", int: "an integer", float: "a number", str: "a string"}
    return names.get(hint, getattr(hint, "__name__", str(hint)))


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
