"""Every default is written once: a settings dataclass's field default is the `default` preset, the other presets
and dpi's defaults file set only what differs from it, and the checkout's config.yaml sets nothing (it lists what a
user edits, commented)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from dpi.config.pipeline import DEFAULT_CONFIG, Pipeline, plain, read_yaml, resolve_config
from dpi.config.validation import SECTIONS
from dpi.io.settings import field_default

ROOT = Path(__file__).resolve().parent.parent


def dataclass_defaults() -> dict[str, Any]:
    """The config as the settings dataclasses alone fill it: each section they own, every field its default."""
    from dpi.config.validation import builder
    from dpi.solve.methods import METHODS, method_config
    from dpi.solve.optimize import flat_config

    out: dict[str, Any] = {}
    for path, cls in SECTIONS.items():
        *parents, leaf = path.split(".")
        target = out
        for key in parents:
            target = target.setdefault(key, {})
        target[leaf] = plain(builder(cls)({}))
    settings = {m: method_config(m, {}) for m in METHODS}
    out["method_params"] = {m: flat_config(s) if hasattr(s, "optimize") else plain(s) for m, s in settings.items()}
    return out


def repeats(values: Any, defaults: Any, path: str = "") -> list[str]:
    """The keys of `values` whose value equals the dataclasses' default at the same place."""
    if isinstance(values, dict) and isinstance(defaults, dict):
        return [hit for key, value in values.items() if key in defaults
                for hit in repeats(value, defaults[key], f"{path}.{key}" if path else key)]
    return [path] if values == defaults else []


def test_the_default_preset_is_the_dataclasses_defaults():
    assert read_yaml(DEFAULT_CONFIG)["presets"]["default"] == {}


def test_no_preset_or_defaults_file_key_repeats_a_dataclass_default():
    base = read_yaml(DEFAULT_CONFIG)
    defaults = dataclass_defaults()
    found = repeats({k: v for k, v in base.items() if k != "presets"}, defaults)
    for name, preset in base["presets"].items():
        found += [f"presets.{name}.{key}" for key in repeats(preset, defaults)]
    assert found == [], "set in a settings dataclass already: " + ", ".join(found)


def test_the_checkouts_config_sets_nothing():
    """config.yaml lists the keys a user edits, commented: its values are dpi's defaults, not copies of them."""
    assert yaml.safe_load((ROOT / "config.yaml").read_text()) is None


def test_a_fields_default_is_the_one_its_class_declares():
    from dpi.solve.dps.refine import RefineConfig
    from dpi.solve.init import InitConfig
    from dpi.solve.problem import ProblemConfig

    config = Pipeline(resolve_config())
    assert config.solve_settings().problem.env_height == field_default(ProblemConfig, "env_height")
    assert config.init_settings.iterations == field_default(InitConfig, "iterations")
    assert config.method_settings("dps").refine.iterations == field_default(RefineConfig, "iterations")
