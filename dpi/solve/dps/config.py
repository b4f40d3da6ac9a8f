"""`dps`'s settings, grouped by concern, and its samplers by name.

method_params.dps holds the shared keys (sampler, steps, the material rates, ...) and one section per
concern: the proximal sampler's settings (`proximal`; the paper's sampler has the reference's, fixed), the
parametric `sun`, the `refine`ment.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from functools import partial
from typing import Annotated, Any, Callable

from pydantic import Field

from dpi.io.settings import Rate, SettingsError, check_keys, settings, settings_from_dict
from dpi.solve.dps.paper import PaperSampler, paper_step
from dpi.solve.dps.proximal import ProximalConfig, proximal_step
from dpi.solve.dps.refine import RefineConfig
from dpi.solve.dps.state import DPSRun, DPSState
from dpi.solve.dps.sun_choice import SunConfig
from dpi.solve.materials import MaterialRates


StepFunction = Callable[[DPSRun, DPSState, int], dict[str, Any]]


@dataclass(frozen=True)
class Sampler:
    """One way of using the data in a reverse step: its settings dataclass, its step function, and the config section
    that holds its settings (None: its settings are fixed, the dataclass's defaults)."""

    settings: type
    step: StepFunction
    section: str | None = None


SAMPLERS: dict[str, Sampler] = {"proximal": Sampler(ProximalConfig, proximal_step, "proximal"),
                                "paper": Sampler(PaperSampler, paper_step)}
"""dps's samplers by name (the `sampler` setting); the first is the default"""


SECTIONS: dict[str, Callable[[Any], Any]] = {"proximal": ProximalConfig.from_dict,
                                             "sun": SunConfig.from_dict,
                                             "refine": partial(settings_from_dict, RefineConfig)}
"""method_params.dps keys that hold a settings section, and the builder of its dataclass from its entry"""


@settings
class DPSConfig(MaterialRates):
    """Settings of the `dps` method (defaults: the CPU preset); the textures' rates: MaterialRates."""

    lr_albedo: Rate = 0.01
    """the albedo's Adam rate, in the loop and the refinement: half the other methods' (MaterialRates); the albedo
    settles under the light instead of chasing each step's residual (docs/studies.md, "the albedo's rate")"""
    sampler: str = next(iter(SAMPLERS))
    """how a reverse step uses the data: proximal (x0-space data steps on the recorded light transport) or paper
    (the reference's gradient guidance through the path tracer)"""
    steps: Annotated[int, Field(ge=2, le=1000)] = 100
    """reverse-diffusion steps (respaced from the prior's 1000; the paper uses 1000)"""
    proximal: ProximalConfig = field(default_factory=ProximalConfig)
    sun: SunConfig = field(default_factory=SunConfig)
    refine: RefineConfig = field(default_factory=RefineConfig)

    @property
    def sampler_settings(self) -> Any:
        """The chosen sampler's own settings: its config section's, or its fixed ones (SAMPLERS)."""
        sampler = SAMPLERS[self.sampler]
        return getattr(self, sampler.section) if sampler.section else sampler.settings()

    @classmethod
    def from_dict(cls, values: dict[str, Any] | None) -> "DPSConfig":
        """Settings from a `method_params.dps` entry: shared keys, and a mapping per section (`sun` also takes a
        bare mode)."""
        values = dict(values or {})
        check_keys(values, [f.name for f in fields(cls)], f"{cls.__name__} setting")
        sections = {}
        for name, make in SECTIONS.items():
            if name in values:
                sections[name] = build_section(name, make, values.pop(name))
        cfg = cls(**values, **sections)
        if cfg.sampler not in SAMPLERS:
            raise SettingsError("sampler", f"must be one of {', '.join(SAMPLERS)}, got {cfg.sampler!r}")
        for name, sampler in SAMPLERS.items():
            if sampler.section in sections and name != cfg.sampler:
                raise SettingsError(sampler.section, f"settings of the {name} sampler, which sampler {cfg.sampler} "
                                                     f"does not use: remove them, or set sampler: {name}")
        return cfg


def build_section(name: str, make: Callable[[Any], Any], values: Any) -> Any:
    """A section's settings from its mapping (the sun's also from a bare mode); errors name the key under the
    section (`proximal.lr_map`)."""
    if not isinstance(values, dict) and not (name == "sun" and isinstance(values, (bool, str))):
        raise SettingsError(name, f"must be a mapping of settings, got {values!r}")
    try:
        return make(values)
    except SettingsError as exc:
        raise SettingsError(f"{name}.{exc.key}", exc.problem) from None
    except ValueError as exc:
        raise SettingsError(name, str(exc)) from None
