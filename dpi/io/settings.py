"""Settings dataclasses from config dicts: one strict constructor for every stage's settings.

A settings class is a pydantic dataclass (`@settings`) whose fields carry their bounds in their annotations
(`steps: Count = 100`, `share: Share = 0.5`), so the bound sits on the field, construction checks it, and the
JSON schema `dpi config --schema` dumps shows it. `settings_from_dict` also rejects unknown keys (naming the
closest valid one) and values of the wrong type. Errors are `SettingsError`s that carry the offending key, so
a config reader can put the key's full path in front (`method_params.dps.steps: must be >= 1, got -5`).
"""

from __future__ import annotations

import copy
import difflib
import functools
from collections.abc import Iterable
from dataclasses import MISSING, fields, is_dataclass
from typing import Annotated, Any, TypeVar

from pydantic import ConfigDict, Field, ValidationError
from pydantic.dataclasses import dataclass as pydantic_dataclass

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


SETTINGS_MODEL = ConfigDict(strict=True, extra="forbid", allow_inf_nan=False, use_attribute_docstrings=True)
"""pydantic's rules for every settings dataclass, the one validation of a setting: unknown fields, values of
another type (strict: 2.5 is no integer, 1 no boolean; an integer is a number), non-finite numbers and values
outside a field's bounds are errors at construction (so also in `dataclasses.replace`)"""

TYPE_WORDS = {"int_type": "an integer", "float_type": "a number", "bool_type": "true or false",
              "string_type": "a string", "tuple_type": "a list", "list_type": "a list", "dict_type": "a mapping",
              "none_required": "null", "literal_error": "one of {expected}"}
"""pydantic's type errors in the words of a config file"""

_C = TypeVar("_C", bound=type)


def settings(cls: _C | None = None, *, frozen: bool = False) -> Any:
    """Make `cls` a settings dataclass: a pydantic dataclass whose fields carry their bounds (`Annotated`); making
    one with a value out of bounds raises one SettingsError naming the key."""
    def wrap(c: _C) -> _C:
        model = pydantic_dataclass(c, config=SETTINGS_MODEL, frozen=frozen)
        validated = model.__init__

        @functools.wraps(validated)
        def checked(self: Any, *args: Any, **kwargs: Any) -> None:
            try:
                validated(self, *args, **kwargs)
            except ValidationError as exc:
                raise settings_error(exc) from None

        model.__init__ = checked
        return model
    return wrap if cls is None else wrap(cls)


Count = Annotated[int, Field(ge=1)]
"""how many of something, at least one"""
Steps = Annotated[int, Field(ge=0)]
"""how many (iterations, levels, votes), zero allowed"""
SamplesPerPixel = Annotated[int, Field(ge=1, le=4096)]
"""path-tracing samples per pixel: more than a few thousand overflow a render's sample budget"""
Rate = Annotated[float, Field(gt=0)]
"""a learning rate or another strictly positive scale"""
Weight = Annotated[float, Field(ge=0)]
"""a non-negative weight, margin or tolerance"""
Fraction = Annotated[float, Field(ge=0, le=1)]
"""a share or threshold in [0, 1]"""
Share = Annotated[float, Field(gt=0, le=1)]
"""a share in (0, 1]"""
MapHeight = Annotated[int, Field(ge=4, le=1024)]
"""rows of an equirectangular map (width twice that)"""
TextureSize = Annotated[int, Field(ge=4, le=4096)]
"""texels along a side of a square texture"""
ImageSize = Annotated[int, Field(ge=8, le=8192)]
"""pixels along an image side"""
Elevation = Annotated[float, Field(ge=-90, le=90)]
"""degrees above the horizon"""
Loose = Field(strict=False)
"""a sequence field: a YAML list is read as the tuple"""


def settings_from_dict(cls: type[T], values: dict[str, Any] | None) -> T:
    """A settings dataclass from a (partial) dict; unknown keys, wrong types and out-of-range values are errors."""
    values = dict(values or {})
    check_keys(values, [f.name for f in fields(cls)], f"{cls.__name__} setting")
    for f in fields(cls):
        if not isinstance(values.get(f.name), dict):
            continue
        section = type(field_default(cls, f.name))
        if is_dataclass(section):  # a nested section, given as a mapping
            try:
                values[f.name] = settings_from_dict(section, values[f.name])
            except SettingsError as exc:
                raise SettingsError(f"{f.name}.{exc.key}", exc.problem) from None
    return cls(**values)


def settings_error(exc: ValidationError) -> SettingsError:
    """pydantic's first error as one `key: must be ..., got ...` line (the members of a union in one line)."""
    errors = exc.errors()
    error = errors[0]
    if error["type"] in TYPE_WORDS:
        # a union's members fail side by side, each with its member's name last in `loc`
        field = error["loc"][:-1] if len(errors) > 1 and errors[1]["loc"][:-1] == error["loc"][:-1] else error["loc"]
        members = [e for e in errors if e["loc"][:len(field)] == field and e["type"] in TYPE_WORDS]
        words = " or ".join(dict.fromkeys(TYPE_WORDS[e["type"]].format(**(e.get("ctx") or {})) for e in members))
        key = ".".join(str(part) for part in field) or "settings"
        return SettingsError(key, f"must be {words}, got {error.get('input')!r}")
    ctx, value = error.get("ctx") or {}, error.get("input")
    if isinstance(ctx.get("error"), SettingsError):  # raised by the class's own check (__post_init__, a validator)
        inner = ctx["error"]
        return SettingsError(".".join([*(str(part) for part in error["loc"]), inner.key]), inner.problem)
    key = ".".join(str(part) for part in error["loc"]) or "settings"
    words = {"greater_than_equal": ">=", "greater_than": ">", "less_than_equal": "<=", "less_than": "<"}
    if error["type"] in words:
        limit = next(iter(ctx.values()))
        return SettingsError(key, f"must be {words[error['type']]} {limit:g}, got {value!r}")
    if error["type"] == "multiple_of":
        return SettingsError(key, f"must be a multiple of {ctx['multiple_of']}, got {value!r}")
    if error["type"] == "value_error":
        return SettingsError(key, f"{error['ctx']['error']}, got {value!r}")
    if error["type"] in ("unexpected_keyword_argument", "extra_forbidden"):
        return SettingsError(key, "unknown setting")
    if error["type"] == "finite_number":
        return SettingsError(key, f"must be a finite number, got {value!r}")
    return SettingsError(key, f"{error['msg'][0].lower()}{error['msg'][1:]}, got {value!r}")


def field_default(cls: type, name: str) -> Any:
    """The default of a dataclass field (a factory's value), e.g. for a command-line option's default."""
    field = next(f for f in fields(cls) if f.name == name)
    return field.default_factory() if field.default is MISSING else field.default


def field_help(cls: type, name: str) -> str | None:
    """A settings field's docstring (pydantic keeps it as the field's description), e.g. for a command-line option's
    help."""
    return cls.__pydantic_fields__[name].description


def check_keys(values: Iterable[Any], known: Iterable[str], what: str) -> None:
    """Fail on the first of `values` (keys, names) not in `known`, suggesting the closest valid one;
    `what` names one of them in the message ("DPSConfig setting", "method")."""
    known = sorted(known)
    unknown = sorted(str(k) for k in values if k not in known)
    if unknown:
        close = difflib.get_close_matches(unknown[0], known, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise SettingsError(unknown[0], f"unknown {what}{hint} (valid: {', '.join(known)})")


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
