"""The workflow config checked before any job runs, with the offending key's path in the one message.

Two passes, both before Snakemake builds the DAG (rules/common.smk):
1. the JSON schema, closed at every level, so a typo anywhere is an unknown key with the closest valid
   one suggested: dpi/data/config.schema.yaml for the workflow's own keys, with each section a settings
   dataclass owns (SECTIONS) generated from that dataclass's fields and their bounds
   (`config_schema`, which `dpi config --schema` prints);
2. every section a settings dataclass owns is built by it: `method_params.{method}` by that
   method's config (dpi.solve.methods, so new dataclass fields are accepted without touching the
   schema), `synthetic.{scene}` by SynthConfig, `preprocess.{stage}` by the stage's config, `render`,
   `problem`, `init`, `adaptive` and each family's `prior` by theirs; each dataclass checks types,
   ranges (dpi.io.settings) and its own values, and its defaults say what a left-out key means.
Prior families are checked against dpi.capture.PRIORS. The quality presets are checked the same way,
whether chosen or not.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import yaml
from jsonschema import Draft202012Validator, validators
from jsonschema.exceptions import ValidationError, best_match
from pydantic import TypeAdapter

from dpi.capture import PRIORS
from dpi.io.layout import Layout
from dpi.io.settings import SettingsError, check_keys, settings_from_dict
from dpi.preprocess.geometry import GeometryConfig
from dpi.preprocess.masks import MaskConfig
from dpi.preprocess.sfm import SfMConfig
from dpi.preprocess.uv import UVConfig
from dpi.prior.train import PriorJobConfig
from dpi.render.renderer import RenderConfig
from dpi.solve.adaptive import AdaptiveConfig
from dpi.solve.init import InitConfig
from dpi.solve.methods import METHODS, method_config
from dpi.solve.problem import ProblemConfig
from dpi.synth.capture import SynthConfig

SECTIONS: dict[str, type] = {"render": RenderConfig, "problem": ProblemConfig, "init": InitConfig,
                              "adaptive": AdaptiveConfig, "preprocess.sfm": SfMConfig, "preprocess.masks": MaskConfig,
                              "preprocess.geometry": GeometryConfig, "preprocess.uv": UVConfig}
"""config sections (key paths) each owned by one settings dataclass: their schema is generated from it, and it
builds them"""


def builder(cls: type) -> Callable[[dict], Any]:
    """The builder of a settings dataclass from its config section: its own `from_dict`, else settings_from_dict."""
    return getattr(cls, "from_dict", None) or partial(settings_from_dict, cls)


def preprocess_settings() -> dict[str, Callable[[dict], Any]]:
    """preprocess stage -> the builder of its settings dataclass from its config section."""
    return {path.removeprefix("preprocess."): builder(cls) for path, cls in SECTIONS.items()
            if path.startswith("preprocess.")}


def config_schema(schema_path: str | Path) -> dict[str, Any]:
    """The config's JSON schema: the file's, with each of SECTIONS generated from its settings dataclass."""
    schema = yaml.safe_load(Path(schema_path).read_text())
    for path, cls in SECTIONS.items():
        node = schema
        for key in path.split("."):
            node = node["properties"][key]
        node.clear()
        node.update(TypeAdapter(cls).json_schema())
    return schema


StrictValidator = validators.extend(Draft202012Validator, type_checker=Draft202012Validator.TYPE_CHECKER.redefine(
    "integer", lambda _, value: isinstance(value, int) and not isinstance(value, bool)))
"""the schema's validator with YAML's integers only as `integer` (JSON Schema also takes 2.0, which would pass
the check and fail later as a count)"""


class ConfigError(ValueError):
    """The workflow config is invalid; the message starts with the key's path (`method_params.dps.steps: ...`)."""


def check_config(config: dict[str, Any], schema_path: str | Path) -> None:
    """Raise one ConfigError for the first problem of any quality preset of `config`, then of `config` itself
    (the chosen preset applied)."""
    schema = config_schema(schema_path)
    partial = {k: v for k, v in schema.items() if k != "required"}
    for name, preset in config.get("presets", {}).items():
        check_against(preset, partial, f"presets.{name}")
    check_against(config, schema, "")
    problem = Layout.from_config(config).problem(config["scenes"])
    if problem:
        raise ConfigError(problem)


def check_against(config: dict[str, Any], schema: dict[str, Any], prefix: str) -> None:
    """The schema pass, then the settings dataclasses, on a config (or a preset's part of one at `prefix`)."""
    error = best_match(StrictValidator(schema).iter_errors(config))
    if error is not None:
        raise ConfigError(schema_message(error, prefix))
    check_methods(config, prefix)
    for scene, entry in config.get("synthetic", {}).items():
        where = join(prefix, "synthetic", scene)
        build(SynthConfig.from_dict, entry, where)
        check_family(entry.get("prior"), f"{where}.prior")
    for path, cls in SECTIONS.items():
        values = section(config, path)
        if values is not None:
            build(builder(cls), values, join(prefix, path))
    illumination = config.get("illumination_prior", {})
    check_family(illumination.get("family"), join(prefix, "illumination_prior.family"))
    for family in illumination.get("checkpoints", {}):
        check_family(family, join(prefix, "illumination_prior.checkpoints", family))
    check_prior_section(config.get("prior", {}), join(prefix, "prior"))


def check_family(family: str | None, where: str) -> None:
    """A prior family name (None: not given) is one of dpi.capture.PRIORS."""
    if family is not None and family not in PRIORS:
        raise ConfigError(f"{where}: must be one of {', '.join(PRIORS)}, got {family!r}")


def check_prior_section(values: dict[str, Any], where: str) -> None:
    """The `prior` section: shared keys, and per-family overrides under a family's name; each family's merged
    settings build its PriorJobConfig."""
    shared = {k: v for k, v in values.items() if not isinstance(v, dict)}
    build(PriorJobConfig.from_dict, shared, where)
    for family, own in values.items():
        if isinstance(own, dict):
            check_family(family, join(where, family))
            build(PriorJobConfig.from_dict, {**shared, **own}, join(where, family))


def check_methods(config: dict[str, Any], prefix: str) -> None:
    """Every method listed or under method_params is known, and its entry (less `samples`) builds its settings."""
    for i, method in enumerate(config.get("methods", [])):
        try:
            check_keys([method], METHODS, "method")
        except SettingsError as exc:
            raise ConfigError(f"{join(prefix, 'methods', str(i))}: {method!r} is an {exc.problem}") from None
    params = config.get("method_params", {})
    wrap(lambda: check_keys(params, METHODS, "method"), join(prefix, "method_params"))
    for method, values in params.items():
        build(lambda v, m=method: method_config(m, v), {k: v for k, v in values.items() if k != "samples"},
              join(prefix, "method_params", method))


def build(make: Callable[[dict], Any], values: dict[str, Any], where: str) -> None:
    """Build a section's settings with `make`; its errors become ConfigErrors at the section's key path."""
    wrap(lambda: make(values), where)


def wrap(check: Callable[[], Any], where: str) -> None:
    """Run `check`; a SettingsError becomes a ConfigError at `where`.key, another ValueError or TypeError one
    at `where`."""
    try:
        check()
    except SettingsError as exc:
        raise ConfigError(f"{join(where, exc.key)}: {exc.problem}") from None
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"{where}: {exc}") from None


def schema_message(error: ValidationError, prefix: str) -> str:
    """A schema violation as `key.path: problem`; an unknown key names the closest valid one."""
    where = join(prefix, *(str(p) for p in error.absolute_path))
    bounds = {"minimum": ">=", "maximum": "<=", "exclusiveMinimum": ">", "exclusiveMaximum": "<"}
    if error.validator in bounds:
        return f"{where}: must be {bounds[error.validator]} {error.validator_value:g}, got {error.instance!r}"
    if error.validator == "pattern":
        return f"{where}: {error.instance!r} is not a plain name (letters, digits, _ . + -, not starting with . " \
               "or -, at most 64 characters)"
    if error.validator == "enum":
        return f"{where}: must be one of {', '.join(map(str, error.validator_value))}, got {error.instance!r}"
    if error.validator == "additionalProperties":
        known = error.schema.get("properties", {})
        try:
            check_keys(error.instance, known, "key")
        except SettingsError as exc:
            return f"{join(where, exc.key)}: {exc.problem}"
    return f"{where or 'config'}: {error.message}"


def section(config: dict[str, Any], path: str) -> dict[str, Any] | None:
    """The dict at a dotted key path of the config, or None where it is absent."""
    for key in path.split("."):
        if not isinstance(config, dict) or key not in config:
            return None
        config = config[key]
    return config


def join(*parts: str) -> str:
    """A dotted key path of the non-empty parts."""
    return ".".join(p for p in parts if p)
