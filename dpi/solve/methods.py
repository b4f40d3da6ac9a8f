"""The posterior methods and the settings dataclass of each: one list for the stages and the config check."""

from __future__ import annotations

from typing import Any

from dpi.solve.classic import ClassicConfig
from dpi.solve.dip import DIPConfig
from dpi.solve.dps import DPSConfig
from dpi.solve.priors import PRIOR_NAMES
from dpi.solve.sds import SDSConfig

METHOD_CONFIGS: dict[str, type] = {**dict.fromkeys(PRIOR_NAMES, ClassicConfig), "dip": DIPConfig, "dps": DPSConfig,
                                   "sds": SDSConfig}
"""method name -> settings dataclass; a `method_params` entry is that class's `from_dict` input"""
METHODS = tuple(METHOD_CONFIGS)
DIFFUSION_METHODS = ("dps", "sds")
"""methods that use the diffusion prior"""


def method_config(method: str, values: dict[str, Any] | None) -> Any:
    """The settings of `method` from its `method_params` entry (without `samples`); errors name the bad key."""
    if method not in METHOD_CONFIGS:
        raise ValueError(f"unknown method {method!r}; available: {', '.join(METHODS)}")
    return METHOD_CONFIGS[method].from_dict(values or {})
