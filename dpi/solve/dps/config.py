"""`dps`'s settings, grouped by concern, and its samplers by name.

method_params.dps holds the shared keys (sampler, steps, the material rates, ...) and one section per
concern: each sampler's own settings (`proximal`, `paper`), the parametric `sun`, the `refine`ment.
A sampler owns its settings dataclass and its defaults; only the chosen sampler's section is used.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from functools import partial
from typing import Any, Callable

from dpi.materials import MaterialRates
from dpi.settings import SettingsError, check_keys, check_values, settings_from_dict
from dpi.solve.dps.paper import PaperSettings, paper_step
from dpi.solve.dps.proximal import ProximalSettings, proximal_step
from dpi.solve.dps.refine import RefineSettings
from dpi.solve.dps.state import DPSRun, DPSState
from dpi.solve.dps.sun import SunSettings

StepFunction = Callable[[DPSRun, DPSState, int], dict[str, Any]]


@dataclass(frozen=True)
class Sampler:
    """One way of using the data in a reverse step: its settings dataclass and its step function."""

    settings: type
    step: StepFunction


SAMPLERS: dict[str, Sampler] = {"proximal": Sampler(ProximalSettings, proximal_step),
                                "paper": Sampler(PaperSettings, paper_step)}
"""dps's samplers by name (the `sampler` setting and its section's key); the first is the default"""

SECTIONS: dict[str, Callable[[Any], Any]] = {**{name: s.settings.from_dict for name, s in SAMPLERS.items()},
                                             "sun": SunSettings.from_dict,
                                             "refine": partial(settings_from_dict, RefineSettings)}
"""method_params.dps keys that hold a settings section, and the builder of its dataclass from its entry"""

MOVED: dict[str, str] = {
    **{key: f"proximal.{key}" for key in ("inner_steps", "lr_map", "prox_weight", "noise_mix", "material_start")},
    **{key: f"paper.{key}" for key in ("guidance_bound", "rho_start", "rho_end", "rho_schedule", "rho_switch")},
    "views_per_step": "paper.views_per_step", "start_noise": "<sampler>.start_noise",
    "refine_iterations": "refine.iterations", "refine_views_per_step": "refine.views_per_step",
    "refine_lr_gain": "refine.lr_gain", "refine_lr_texels": "refine.lr_texels",
    **{f"sun_{key}": f"sun.{key}" for key in ("radius_deg", "min_roughness", "min_share", "share", "prior_weight")},
}
"""flat keys of the settings before they were grouped -> where they are now"""
REMOVED = ("map_update", "warm_start", "refine_env", "refine_gain_order", "lr_sun", "lr_sun_uv", "refine_lr_env",
           "annealed", "spp")
"""flat keys of variants that lost their study (docs/studies.md)"""
REMOVED_SAMPLERS = ("gibbs",)
"""samplers that lost their study (docs/studies.md): a config naming one, or its section, gets an error saying so"""


@dataclass
class DPSConfig(MaterialRates):
    """Settings of the `dps` method (defaults: the CPU preset); the textures' rates: MaterialRates."""

    lr_albedo: float = 0.01
    """the albedo's Adam rate, in the loop and the refinement: half the other methods' (MaterialRates); the albedo
    settles under the light instead of chasing each step's residual (posterior study, ambiguous: albedo MSE -27 %
    on 18 of 18 samples, relight PSNR-H +0.5 dB, views +0.2, env -0.1; at 0.005 the views lose 1.5 dB;
    docs/studies.md "the albedo's rate")"""
    sampler: str = next(iter(SAMPLERS))
    """how a reverse step uses the data: proximal (x0-space data steps on the recorded light transport) or paper
    (the reference's gradient guidance through the path tracer)"""
    steps: int = 100
    """reverse-diffusion steps (respaced from the prior's 1000; the paper uses 1000)"""
    radiance_scale: float | None = None
    """scene radiance per unit of the prior's normalised radiance (None: estimated from the init)"""
    strip_frames: int = 8
    """x0_hat snapshots kept for the progress strip"""
    proximal: ProximalSettings = field(default_factory=ProximalSettings)
    paper: PaperSettings = field(default_factory=PaperSettings)
    sun: SunSettings = field(default_factory=SunSettings)
    refine: RefineSettings = field(default_factory=RefineSettings)

    @property
    def sampler_settings(self) -> Any:
        """The chosen sampler's own settings."""
        return getattr(self, self.sampler)

    @classmethod
    def from_dict(cls, values: dict[str, Any] | None) -> "DPSConfig":
        """Settings from a `method_params.dps` entry: shared keys, and a mapping per section (`sun` also takes a
        bare mode). A key of the flat layout before the sections is an error that names its new place."""
        values = dict(values or {})
        for key in values:
            if key in MOVED:
                raise SettingsError(key, f"moved to {MOVED[key]} (a section of method_params.dps)")
            if key in REMOVED or key in REMOVED_SAMPLERS:
                raise SettingsError(key, "removed: that variant lost its study (docs/studies.md)")
        if values.get("sampler") in REMOVED_SAMPLERS:
            raise SettingsError("sampler", f"{values['sampler']!r} was removed: it lost its study (docs/studies.md); "
                                           f"use one of {', '.join(SAMPLERS)}")
        check_keys(values, [f.name for f in fields(cls)], f"{cls.__name__} setting")
        sections = {}
        for name, make in SECTIONS.items():
            if name in values:
                sections[name] = build_section(name, make, values.pop(name))
        check_values(cls, values)
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
