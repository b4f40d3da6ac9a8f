"""The pipeline's facts, each with one owner: how a config is resolved, what it means in typed settings,
where every artefact lives (dpi.io.layout) and which methods exist (dpi.solve.methods).

**Config resolution** (`resolve_config`), the same for the Snakemake workflow and the `dpi` command:

1. dpi's defaults, `dpi/data/config.yaml` (shipped in the package; `dpi config` prints the result);
2. `config.yaml` in the working directory, when there is one (in the checkout: the top-level file a user
   edits, which the Snakefile reads the same way, through this function);
3. each file given with `snakemake --configfile` or `dpi --config`, in order, and Snakemake's
   `--config key=value`, merged key by key as Snakemake merges config files (a dict is merged into
   the dict below it, anything else replaces);
4. the quality preset fills what is still unset (`dpi.io.settings.apply_preset`);
5. the schema and the settings dataclasses check it (`dpi.config.validation`), with the key's path in
   the one message.

What a key left out means is said once, by its settings dataclass (render, problem, init, adaptive,
preprocess stages, method_params, synthetic entries, prior) or by the defaults file (the rest).
`Pipeline` answers the questions the rules and the command share: a stage's typed settings, a
method's sample count, a scene's prior family and checkpoint, which inputs a scene lacks.
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass, fields, is_dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

from dpi.capture import PRIORS, inspect_capture, read_scene_options
from dpi.config.validation import check_config, preprocess_settings
from dpi.io.layout import Layout, package_data
from dpi.io.settings import apply_preset
from dpi.io.structured import read_yaml as read_structured_yaml
from dpi.prior.sample import DEFAULT_FAMILY, family_checkpoint
from dpi.prior.train import PriorJobConfig
from dpi.solve.adaptive import AdaptiveConfig
from dpi.solve.init import InitConfig
from dpi.solve.methods import REGISTRY, method_config
from dpi.solve.optimize import OptimizeConfig, flat_config
from dpi.solve.problem import SolveConfig
from dpi.synth.capture import SynthConfig

DEFAULT_CONFIG = package_data("config.yaml")
CONFIG_SCHEMA = package_data("config.schema.yaml")
LOCAL_CONFIG = Path("config.yaml")
"""a run directory's own settings (the checkout's top-level config.yaml), read over the defaults when present"""


def merge(base: dict[str, Any], override: dict[str, Any]) -> dict[str, Any]:
    """`override` merged into a copy of `base` as Snakemake merges config files: dicts key by key, any other
    value replaces."""
    out = copy.deepcopy(base)
    for key, value in override.items():
        out[key] = merge(out[key], value) if isinstance(value, dict) and isinstance(out.get(key), dict) \
            else copy.deepcopy(value)
    return out


def read_yaml(path: str | Path) -> dict[str, Any]:
    """A config file's mapping ({} for an empty file), read within dpi.io.structured's limits."""
    values = read_structured_yaml(path) or {}
    if not isinstance(values, dict):
        raise ValueError(f"{path}: a config file holds a mapping of settings, got {type(values).__name__}")
    return values


def resolve_config(*overrides: dict[str, Any]) -> dict[str, Any]:
    """The checked workflow config: the defaults, ./config.yaml when present, then `overrides` in order, then
    the quality preset (module docstring). Raises dpi.config.validation.ConfigError naming the key."""
    config = read_yaml(DEFAULT_CONFIG)
    for layer in ([read_yaml(LOCAL_CONFIG)] if LOCAL_CONFIG.is_file() else []) + list(overrides):
        config = merge(config, layer)
    apply_preset(config)
    check_config(config, CONFIG_SCHEMA)
    return config


def load_pipeline(config_files: list[str | Path] = ()) -> "Pipeline":
    """The pipeline of the defaults, ./config.yaml and `config_files` (the `dpi --config` files)."""
    return Pipeline(resolve_config(*(read_yaml(path) for path in config_files)))


@dataclass(frozen=True)
class Pipeline:
    """A resolved config and the typed answers derived from it."""

    config: dict[str, Any]

    @cached_property
    def layout(self) -> Layout:
        return Layout.from_config(self.config)

    @property
    def scenes(self) -> list[str]:
        return list(self.config["scenes"])

    @property
    def methods(self) -> list[str]:
        return list(self.config["methods"])

    def samples(self, method: str) -> int:
        """Posterior samples of a method (its own `samples`, else the global one)."""
        return self.config["method_params"].get(method, {}).get("samples", self.config["samples"])

    def method_params(self, method: str) -> dict[str, Any]:
        """A method's `method_params` entry without the sample count (so adding samples reruns no job)."""
        return {k: v for k, v in self.config["method_params"].get(method, {}).items() if k != "samples"}

    def method_settings(self, method: str) -> Any:
        """A method's settings dataclass, built from its entry."""
        return method_config(method, self.method_params(method))

    def solve_settings(self, threads: int | None = None) -> SolveConfig:
        """Renderer and problem settings shared by init, methods and evaluation, on `threads` threads."""
        return SolveConfig.from_config(self.config, threads)

    @property
    def init_settings(self) -> InitConfig:
        return InitConfig.from_dict(self.config.get("init"))

    @property
    def adaptive(self) -> AdaptiveConfig:
        return AdaptiveConfig.from_dict(self.config["adaptive"])

    @property
    def evaluate_spp(self) -> int:
        return self.config["evaluate"]["spp"]

    def threads(self, kind: str) -> int:
        """Threads of a job kind (synth, init, sample, evaluate, preprocess)."""
        return self.config["threads"][kind]

    def is_synthetic(self, scene: str) -> bool:
        """Scenes under `synthetic:` are rendered by `dpi synth` when their capture folder is missing."""
        return scene in self.config["synthetic"]

    def synth_settings(self, scene: str) -> SynthConfig:
        return SynthConfig.from_dict(self.config["synthetic"][scene])

    def given(self, scene: str) -> dict[str, bool]:
        """What a scene's capture gives (cameras, masks, mesh, mesh_has_uv), known before it is rendered for a
        synthetic scene."""
        if self.is_synthetic(scene):
            synth = self.synth_settings(scene)
            have = not synth.photos_only
            return {**dict.fromkeys(("cameras", "masks", "mesh"), have), "mesh_has_uv": have and not synth.scan_faces}
        return inspect_capture(self.layout.capture_dir(scene))

    def scene_family(self, scene: str) -> str:
        """Prior family of a scene: `prior` of its synthetic entry or scene.yaml, else illumination_prior.family,
        else dpi.prior.sample.DEFAULT_FAMILY."""
        own = (self.synth_settings(scene).prior if self.is_synthetic(scene)
               else read_scene_options(self.layout.capture_dir(scene)).get("prior"))
        return own or self.config["illumination_prior"].get("family", DEFAULT_FAMILY)

    def prior_checkpoint(self, scene: str) -> Path:
        """The diffusion prior of a scene's family: illumination_prior.checkpoints, else the shipped model."""
        family = self.scene_family(scene)
        return family_checkpoint(family, self.config["illumination_prior"]["checkpoints"])

    def method_prior(self, scene: str, method: str) -> Path | None:
        """The prior checkpoint a method's job reads (None for methods without the diffusion prior)."""
        return self.prior_checkpoint(scene) if REGISTRY[method].needs_prior else None

    def prior_job(self, family: str) -> PriorJobConfig:
        """Dataset and training settings of a family's prior (config `prior`, then `prior.<family>`)."""
        section = self.config.get("prior", {})
        shared = {k: v for k, v in section.items() if not isinstance(v, dict)}
        return PriorJobConfig.from_dict({**shared, **section.get(family, {})})

    def prior_section(self, family: str) -> dict[str, Any]:
        """A family's `prior` settings in full, as the config writes them (the training fields beside the job's)."""
        job = self.prior_job(family)
        return {**{k: v for k, v in plain(job).items() if k != "train"}, **plain(job.train_config())}

    def describe(self) -> dict[str, Any]:
        """The config with each section a settings dataclass owns written out in full (what a left-out key
        means), as `dpi config` prints it."""
        out = copy.deepcopy(self.config)
        solve = self.solve_settings()
        out["render"] = {k: v for k, v in asdict(solve.render).items() if k != "threads"}
        out["problem"] = asdict(solve.problem)
        out["init"] = plain(self.init_settings)
        out["adaptive"] = plain(self.adaptive)
        out["illumination_prior"] = {**out["illumination_prior"], "family": self.config["illumination_prior"].get(
            "family", DEFAULT_FAMILY)}
        out["synthetic"] = {scene: plain(self.synth_settings(scene)) for scene in self.config["synthetic"]}
        out["method_params"] = {m: {**({"samples": self.samples(m)} if m in self.methods else {}),
                                    **method_entry(self.method_settings(m))} for m in self.config["method_params"]}
        out["preprocess"] = {stage: plain(make(self.config["preprocess"][stage]))
                             for stage, make in preprocess_settings().items()}
        out["prior"] = {family: self.prior_section(family) for family in PRIORS}
        return out


def method_entry(settings: Any) -> dict[str, Any]:
    """A method's settings as its `method_params` entry takes them back: flat for the settings whose `optimize`
    section is read from the entry's own level (dpi.solve.optimize.method_config_from_dict), else `plain`."""
    return plain(flat_config(settings)) if isinstance(getattr(settings, "optimize", None), OptimizeConfig) \
        else plain(settings)


def plain(settings: Any) -> Any:
    """A settings dataclass as YAML-ready plain values (nested dataclasses as dicts, tuples as lists)."""
    if is_dataclass(settings):
        return {f.name: plain(getattr(settings, f.name)) for f in fields(settings)}
    if isinstance(settings, (list, tuple)):
        return [plain(v) for v in settings]
    return settings
