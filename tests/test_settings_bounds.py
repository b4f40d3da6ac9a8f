"""Property test of the settings' bounds: values drawn outside a field's schema bounds are one-line errors naming
the key; values drawn inside are accepted and a tiny `dps` sample runs on them without crashing."""

from typing import Any

import numpy as np
import pytest
import torch
from pydantic import TypeAdapter

from dpi.capture import load_capture
from dpi.io.settings import SettingsError
from dpi.render.renderer import RenderConfig
from dpi.solve.dps import DPSConfig, dps_sample
from dpi.solve.init import InitConfig, path_traced_init
from dpi.solve.problem import InverseProblem, ProblemConfig
from tests.test_dps import tiny_prior

CHEAP = {"steps": 4, "iterations": 3, "pixels": 256, "spp": 4}
"""caps for draws inside the bounds where a large value only costs time"""


def numeric_fields(schema: dict[str, Any], defs: dict[str, Any], prefix: tuple[str, ...] = ()) -> dict:
    """key path -> the field's JSON schema, for every numeric field, through nested sections."""
    out = {}
    for name, field in schema.get("properties", {}).items():
        if "$ref" in field:
            out |= numeric_fields(defs[field["$ref"].split("/")[-1]], defs, (*prefix, name))
            continue
        options = field.get("anyOf", [field])
        numeric = next((o for o in options if o.get("type") in ("integer", "number")), None)
        if numeric:
            out[(*prefix, name)] = numeric
    return out


SCHEMA = TypeAdapter(DPSConfig).json_schema()
NUMERIC = numeric_fields(SCHEMA, SCHEMA.get("$defs", {}))
FIELDS = {path: field for path, field in NUMERIC.items()
          if any(k in field for k in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"))}
"""every numeric field with a bound"""


def nested(path: tuple[str, ...], value: Any) -> dict:
    """A method_params.dps entry setting one key path."""
    for key in reversed(path):
        value = {key: value}
    return value


def merge(a: dict, b: dict) -> dict:
    """`a` with `b` written over it, nested dicts key by key."""
    out = dict(a)
    for k, v in b.items():
        out[k] = merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def outside(field: dict) -> list[float]:
    """Values just outside each bound of a field."""
    step = 1 if field["type"] == "integer" else 1e-3
    values = []
    if "minimum" in field:
        values.append(field["minimum"] - step)
    if "exclusiveMinimum" in field:
        values.append(field["exclusiveMinimum"])
    if "maximum" in field:
        values.append(field["maximum"] + step)
    if "exclusiveMaximum" in field:
        values.append(field["exclusiveMaximum"])
    return values


def inside(field: dict, name: str, rng: np.random.Generator) -> float:
    """A random value inside a field's bounds (large ones capped by CHEAP where they only cost time)."""
    low = field.get("minimum", field.get("exclusiveMinimum", 0.0))
    high = field.get("maximum", field.get("exclusiveMaximum", low + 4))
    high = min(high, CHEAP.get(name, high))
    if field["type"] == "integer":
        low = int(np.ceil(low + (1e-9 if "exclusiveMinimum" in field else 0)))
        value = int(rng.integers(low, max(low, int(high)) + 1))
        step = field.get("multipleOf", 1)
        return max(low, value - value % step)
    value = float(rng.uniform(low, high))
    return value if value > low or "exclusiveMinimum" not in field else (low + high) / 2


@pytest.mark.parametrize("path", list(FIELDS), ids=".".join)
def test_a_value_outside_a_fields_bounds_is_one_line_naming_it(path):
    for value in outside(FIELDS[path]):
        with pytest.raises(SettingsError) as info:
            DPSConfig.from_dict(nested(path, value))
        assert str(info.value).startswith(".".join(path) + ": must be ") and "\n" not in str(info.value)


def test_the_bounds_cover_the_settings_a_sample_reads():
    assert FIELDS.keys() == NUMERIC.keys() and len(FIELDS) >= 15
    assert ("proximal", "perturb") in FIELDS and ("refine", "iterations") in FIELDS


@pytest.fixture(scope="module")
def problem_and_init(tiny_capture):
    problem = InverseProblem(load_capture(tiny_capture), ProblemConfig(env_height=4, texture_size=8),
                             RenderConfig(spp=4, threads=2))
    return problem, path_traced_init(problem, InitConfig(iterations=2, reading="rough"), seed=0, progress=False).kept


@pytest.mark.parametrize("draw", range(4))
def test_settings_drawn_inside_the_bounds_run_a_tiny_sample(problem_and_init, draw):
    """Each draw sets a random third of the bounded fields to random values inside their bounds."""
    problem, init = problem_and_init
    rng = np.random.default_rng(draw)
    entry = {"steps": 3, "refine": {"iterations": 2}, "sampler": ("proximal", "paper")[draw % 2]}
    paths = [p for p in FIELDS if entry["sampler"] == "proximal" or p[0] != "proximal"]  # the paper's are fixed
    for i in rng.choice(len(paths), size=len(paths) // 3, replace=False):
        entry = merge(entry, nested(paths[i], inside(FIELDS[paths[i]], paths[i][-1], rng)))
    cfg = DPSConfig.from_dict(entry)
    d = dps_sample(problem, tiny_prior(), init, cfg, seed=draw, progress=False).decomposition
    assert torch.isfinite(d.env).all() and all(torch.isfinite(t).all() for _, t in d.materials.items())
