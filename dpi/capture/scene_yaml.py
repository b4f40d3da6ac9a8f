"""scene.yaml: a capture's own options (prior family, held-out views, radiance scale, object, focal length), checked
key by key."""

from __future__ import annotations

import math
import os
from pathlib import Path

import yaml

from dpi.cameras import json_value
from dpi.capture.model import CaptureError

SCENE_YAML_KEYS = ("prior", "held_out", "radiance_scale", "object", "notes", "focal_length_px")


PRIORS = ("indoor", "outdoor")


def yaml_problem(exc: yaml.YAMLError) -> str:
    """A YAML parse error on one line: the problem and where."""
    mark = getattr(exc, "problem_mark", None)
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
    return f"{getattr(exc, 'problem', None) or exc}{where}"


def read_scene_options(root: str | os.PathLike) -> dict:
    """Validated contents of a capture's scene.yaml ({} without one); the workflow reads it before building the DAG."""
    path = Path(root) / "scene.yaml"
    if not path.is_file():
        return {}
    try:
        options = yaml.safe_load(path.read_text())
    except UnicodeDecodeError as exc:
        raise CaptureError(f"{path}: invalid YAML (not UTF-8 text: {exc.reason})") from exc
    except yaml.YAMLError as exc:
        raise CaptureError(f"{path}: invalid YAML ({yaml_problem(exc)})") from exc
    options = {} if options is None else options
    if not isinstance(options, dict):
        raise CaptureError(f"{path}: not a mapping of options (got {type(options).__name__})")
    unknown = sorted(str(k) for k in options if k not in SCENE_YAML_KEYS)
    if unknown:
        raise CaptureError(f"{path}: unknown keys {unknown} (allowed: {', '.join(SCENE_YAML_KEYS)})")
    if "prior" in options and options["prior"] not in PRIORS:
        raise CaptureError(f"{path}: prior must be one of {', '.join(PRIORS)}, got {options['prior']!r}")
    if "held_out" in options:
        options["held_out"] = _held_out_names(path, options["held_out"])
    for key, unit in (("radiance_scale", ""), ("focal_length_px", " (pixels)")):
        if key in options:
            options[key] = _positive_number(path, key, options[key], unit)
    for key in ("object", "notes"):
        if key in options and not isinstance(options[key], str):
            raise CaptureError(f"{path}: {key} must be a string, got {json_value(options[key])}")
    return options


def _held_out_names(path: Path, value: object) -> list[str]:
    """scene.yaml's held_out: a list of image names (strings, or integers for numbered images; not booleans)."""
    if not isinstance(value, list):
        raise CaptureError(f"{path}: held_out must be a list of image names, got {json_value(value)}")
    for i, name in enumerate(value):
        if isinstance(name, bool) or not isinstance(name, (str, int)):
            raise CaptureError(f"{path}: held_out[{i}] must be an image name (a string), got {json_value(name)}")
    return [str(name) for name in value]


def _positive_number(path: Path, key: str, value: object, unit: str) -> float:
    """A scene.yaml number that must be positive and finite (a YAML number: not a boolean, not a quoted string)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
        raise CaptureError(f"{path}: {key} must be a positive number{unit}, got {json_value(value)}")
    return float(value)
