"""`dps`'s settings, grouped by concern, and its samplers by name.

method_params.dps holds the shared keys (sampler, steps, the material rates, ...) and one section per
concern: the proximal sampler's settings (`proximal`; the paper's sampler has the reference's, fixed), the
parametric `sun`, the `refine`ment.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from functools import partial
from typing import Annotated, Any, Callable

from pydantic import Field

from dpi.io.settings import Count, Rate, SettingsError, Steps, check_keys, settings, settings_from_dict
from dpi.solve.decomposition import Decomposition
from dpi.solve.dps.paper import PaperSampler, paper_step
from dpi.solve.dps.proximal import ProximalConfig, proximal_step
from dpi.solve.dps.refine import RefineConfig
from dpi.solve.dps.state import DPSRun, DPSState
from dpi.solve.dps.sun_choice import SunConfig
from dpi.solve.init import is_glossy
from dpi.solve.materials import MaterialRates


StepFunction = Callable[[DPSRun, DPSState, int], dict[str, Any]]


@dataclass(frozen=True)
class Sampler:
    """One way of using the data in a reverse step: its settings dataclass and its step function."""

    settings: type
    step: StepFunction


SAMPLERS: dict[str, Sampler] = {"proximal": Sampler(ProximalConfig, proximal_step),
                                "paper": Sampler(PaperSampler, paper_step)}
"""dps's samplers by name (the `sampler` setting); the first is the default. The proximal sampler's settings are
a config section; the paper's are the reference's, fixed"""



@settings
class GlossyConfig:
    """What a glossy init (dpi.solve.init.is_glossy) changes in its samples' settings (`method_params.dps.glossy`);
    a rough init's samples run the settings as they are. The sample's log says when it applies."""

    inner_steps: Count = 2
    """the proximal sampler's data updates a step (for its map solve)"""
    map_solve: Steps = 0
    """the proximal sampler's map-solve iterations a step: none (a mirror's views pin its light down where they
    reflect it, and a solve on its finer transport cost env PSNR, docs/studies.md)"""
    refine_factor: Count = 2
    """the refinement runs this many times `refine.iterations` (the loop does not move the roughness a mirror's views
    hinge on)"""
    refine_views: Count = 1
    """views the refinement renders a step: its longer refinement at the cost of the rough one's, and its fit no worse
    (docs/studies.md, "What a glossy sample costs")"""
    lr_texels: Rate = 0.02
    """the polish rate on a map with at least the prior's rows: a mirror's views pin down detail the prior's grid
    cannot hold. A coarser map keeps `refine.lr_texels`: fitting reflections finer than its texels only sharpens it
    away from the light (docs/studies_log.md, "The polish on a coarse map")"""


SECTIONS: dict[str, Callable[[Any], Any]] = {"proximal": ProximalConfig.from_dict,
                                             "sun": SunConfig.from_dict,
                                             "refine": partial(settings_from_dict, RefineConfig),
                                             "glossy": partial(settings_from_dict, GlossyConfig)}
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
    glossy: GlossyConfig = field(default_factory=GlossyConfig)

    @property
    def sampler_settings(self) -> Any:
        """The chosen sampler's own settings (the paper's: its fixed ones)."""
        return self.proximal if self.sampler == "proximal" else PaperSampler()

    def for_init(self, init: Decomposition, prior_rows: int) -> DPSConfig:
        """The settings a sample from `init` runs with, under a prior of `prior_rows` rows: the one place a glossy
        init (dpi.solve.init.is_glossy) changes them, by the `glossy` section (its transport:
        dpi.solve.dps.data_term.sample_transport); a rough init's are these."""
        if not is_glossy(init.materials):
            return self
        glossy = self.glossy
        proximal = replace(self.proximal, inner_steps=glossy.inner_steps, map_solve=glossy.map_solve)
        lr_texels = glossy.lr_texels if init.env.shape[0] >= prior_rows else self.refine.lr_texels
        refine = replace(self.refine, iterations=self.refine.iterations * glossy.refine_factor,
                         views_per_step=glossy.refine_views, lr_texels=lr_texels)
        return replace(self, proximal=proximal, refine=refine)

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
