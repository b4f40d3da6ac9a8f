"""scene.yaml: a capture's own options (prior family, held-out views, radiance scale, object, focal length), checked
key by key."""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

from dpi.capture.cameras import json_value
from dpi.capture.model import CaptureError, inside_capture
from dpi.io.structured import StructuredFileError, read_yaml

SCENE_YAML_KEYS = ("prior", "held_out", "radiance_scale", "object", "notes", "focal_length_px")


PRIORS = ("indoor", "outdoor")
OPTION_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_-]{0,39}")
"""what an option key looks like; other keys are counted in an error, never quoted (they may be a file's lines)"""


def read_scene_options(root: str | os.PathLike) -> dict:
    """Validated contents of a capture's scene.yaml ({} without one); the workflow reads it before building the DAG."""
    path = Path(root) / "scene.yaml"
    if not path.is_file():
        return {}
    inside_capture(root, path, "scene.yaml")
    try:
        options = read_yaml(path)
    except StructuredFileError as exc:
        raise CaptureError(str(exc)) from None
    options = {} if options is None else options
    if not isinstance(options, dict):
        raise CaptureError(f"{path}: not a mapping of options (got {type(options).__name__})")
    unknown = [k for k in options if k not in SCENE_YAML_KEYS]
    if unknown:
        named = sorted(str(k) for k in unknown if isinstance(k, str) and OPTION_NAME.fullmatch(k))
        others = len(unknown) - len(named)
        listed = ", ".join(named) + (f"{' and ' if named else ''}{others} that are not option names" if others else "")
        raise CaptureError(f"{path}: unknown keys: {listed} (allowed: {', '.join(SCENE_YAML_KEYS)})")
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
