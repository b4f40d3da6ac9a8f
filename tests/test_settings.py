"""Strict settings from dicts, and quality presets that fill only what the user leaves unset."""

import copy
from dataclasses import replace
from typing import Annotated

import pytest

from dpi.io.settings import Count, Loose, Rate, SettingsError, apply_preset, settings, settings_from_dict

PRESETS = {"draft": {"render": {"spp": 4}, "method_params": {"dps": {"steps": 25, "refine_iterations": 50}}},
           "paper": {"render": {"spp": 64}, "problem": {"env_height": 64}}}


def test_preset_fills_unset_keys_and_user_keys_win():
    config = {"preset": "draft", "presets": PRESETS, "render": {"max_depth": 5},
              "method_params": {"dps": {"steps": 40}, "none": {"iterations": 10}}}
    apply_preset(config)
    assert config["render"] == {"max_depth": 5, "spp": 4}
    assert config["method_params"] == {"dps": {"steps": 40, "refine_iterations": 50}, "none": {"iterations": 10}}


def test_preset_does_not_alias_the_preset_dicts():
    presets = copy.deepcopy(PRESETS)
    config = apply_preset({"preset": "paper", "presets": presets})
    config["problem"]["env_height"] = 8
    config = apply_preset({"preset": "draft", "presets": presets})
    config["method_params"]["dps"]["steps"] = 1
    assert presets["draft"]["method_params"]["dps"]["steps"] == 25
    assert presets["paper"]["problem"]["env_height"] == 64


def test_unknown_preset_names_the_defined_ones():
    with pytest.raises(ValueError, match="'fast'.*draft, paper"):
        apply_preset({"preset": "fast", "presets": PRESETS})


@settings
class S:
    a: int = 1
    steps: Count = 10
    lr_env: Rate = 0.1
    scale: float | None = None
    names: Annotated[tuple[str, ...], Loose] = ()


def test_settings_from_dict_rejects_unknown_keys_naming_the_closest():
    assert settings_from_dict(S, {"a": 2}).a == 2
    with pytest.raises(SettingsError, match=r"^b: unknown S setting \(valid: a, lr_env, names, scale, steps\)$"):
        settings_from_dict(S, {"b": 1})
    with pytest.raises(SettingsError, match=r"^stepz: unknown S setting; did you mean 'steps'\?") as info:
        settings_from_dict(S, {"stepz": 1})
    assert info.value.key == "stepz"


@pytest.mark.parametrize("values,message", [
    ({"steps": 0}, "steps: must be >= 1, got 0"),
    ({"steps": -5}, "steps: must be >= 1, got -5"),
    ({"steps": 2.5}, "steps: must be an integer, got 2.5"),
    ({"steps": True}, "steps: must be an integer, got True"),
    ({"lr_env": 0}, "lr_env: must be > 0, got 0"),
    ({"lr_env": float("nan")}, "lr_env: must be a finite number, got nan"),
    ({"lr_env": "fast"}, "lr_env: must be a number, got 'fast'"),
    ({"scale": "x"}, "scale: must be a number, got 'x'"),
    ({"names": ["a", 1]}, "names.1: must be a string, got 1"),
])
def test_settings_values_are_checked_by_type_and_field_bounds(values, message):
    with pytest.raises(SettingsError) as info:
        settings_from_dict(S, values)
    assert str(info.value) == message


def test_a_fields_bound_holds_wherever_the_settings_are_made():
    """The bound sits on the field: a direct construction or a `replace` is checked as a config is."""
    with pytest.raises(SettingsError, match="^steps: must be >= 1, got 0$"):
        replace(S(), steps=0)
    with pytest.raises(SettingsError, match="^lr_env: must be > 0, got -1.0$"):
        S(lr_env=-1.0)


def test_valid_values_pass_and_ints_count_as_numbers():
    s = settings_from_dict(S, {"steps": 1, "lr_env": 1, "scale": None, "names": ["a"]})
    assert (s.steps, s.lr_env, s.scale, s.names) == (1, 1, None, ("a",))


def test_settings_error_survives_pickling():
    """A worker process's settings error reaches the parent with its key and message."""
    import pickle

    error = pickle.loads(pickle.dumps(SettingsError("method_params.dps.lr_map", "must be > 0, got 0")))
    assert isinstance(error, SettingsError)
    assert (error.key, error.problem) == ("method_params.dps.lr_map", "must be > 0, got 0")
    assert str(error) == "method_params.dps.lr_map: must be > 0, got 0"
