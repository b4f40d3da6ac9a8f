"""Settings and decision of `dps`'s parametric sun (its geometry: dpi.solve.sun_model).

With a sun the sampled map is the prior's sky plus a point of irradiance at a fitted position; it
starts from the init map's brightest region. Whether a sample gets one is `mode`: on, off, or auto
(on for samplers that model one, with the outdoor prior, for objects that are not glossy, when the
init's bright region carries a share of its energy worth modelling): a glossy object mirrors the light, its views
resolve its sun, and the sun's share prior only costs accuracy there.
"""

from __future__ import annotations

from typing import Any

from dpi.io.settings import SettingsError, Share, Weight, settings, settings_from_dict
from dpi.solve.sun_model import SunExtraction

SUN_MODES = ("auto", "on", "off")
SUN_FAMILIES = ("outdoor",)
"""prior families whose maps get a parametric sun under mode auto"""
LR_SUN = 0.05
"""Adam rate of the sun's log irradiance"""
LR_SUN_UV = 0.003
"""Adam rate of the sun's map coordinates (u spans 360 deg, v 180 deg)"""


MIN_SHARE = 0.05
"""the sun is kept only when that excess carries at least this share of the init map's energy"""


@settings
class SunConfig:
    """A parametric sun next to the prior's sky (method_params.dps.sun)."""

    mode: str = "auto"
    """on, off, or auto (on for samplers that model a sun, with the outdoor prior, for objects that are not glossy)"""
    share: Share = 0.55
    """the share of the map's energy the sun's prior expects: the median over the outdoor generator's clear
    skies with the sun above 10 deg (0.5-0.6 per elevation band; lower under clouds)"""
    prior_weight: Weight = 0.01
    """weight of (logit share - logit `share`)^2 next to the relative data term (0: the data alone)"""

    @classmethod
    def from_dict(cls, values: dict[str, Any] | bool | str) -> "SunConfig":
        """Settings from a `sun` entry; a bare mode (`sun: off`, which YAML reads as a boolean) means that mode."""
        if isinstance(values, (bool, str)):
            values = {"mode": values}
        if isinstance(values.get("mode"), bool):
            values = {**values, "mode": "on" if values["mode"] else "off"}
        settings = settings_from_dict(cls, values)
        if settings.mode not in SUN_MODES:
            raise SettingsError("mode", f"must be one of {', '.join(SUN_MODES)}, got {settings.mode!r}")
        return settings


def wants_sun(settings: SunConfig, sampler_models_sun: bool, family: str, glossy: bool, sun: SunExtraction) -> bool:
    """Whether a sample gets a parametric sun (the module's rule for `mode`); `glossy`: the sample starts as a glossy
    object's (dpi.solve.dps.start.glossy_start)."""
    if settings.mode != "auto":
        return settings.mode == "on"
    return (sampler_models_sun and family in SUN_FAMILIES and not glossy
            and sun.share >= MIN_SHARE)
