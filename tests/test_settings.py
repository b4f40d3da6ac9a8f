"""Strict settings from dicts, and quality presets that fill only what the user leaves unset."""

import copy
from dataclasses import dataclass

import pytest

from dpi.settings import apply_preset, settings_from_dict

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


def test_settings_from_dict_rejects_unknown_keys():
    @dataclass
    class S:
        a: int = 1

    assert settings_from_dict(S, {"a": 2}).a == 2
    with pytest.raises(ValueError, match="unknown S settings \\['b'\\]; valid: a"):
        settings_from_dict(S, {"b": 1})
