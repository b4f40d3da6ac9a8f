"""Bad workflow configs with known answers: every typo and bad value, at any level, stops before any job
with one message that starts with the key's path; the shipped configs pass; a real `snakemake -n` on a
bad config or a bad scene.yaml prints that message and writes nothing."""

from __future__ import annotations

import copy
import subprocess
from pathlib import Path
from typing import Any

import pytest
from capture_helpers import make_capture
from workflow_helpers import REPO, SNAKEMAKE, TINY_CONFIG, write_config

from dpi.config.pipeline import CONFIG_SCHEMA, DEFAULT_CONFIG, read_yaml
from dpi.config.validation import ConfigError, check_config
from dpi.io.settings import apply_preset

SHIPPED = read_yaml(DEFAULT_CONFIG)


def merged(base: dict[str, Any], patch: dict[str, Any]) -> dict[str, Any]:
    """`base` with `patch` written over it, nested dicts key by key."""
    out = copy.deepcopy(base)
    for key, value in patch.items():
        out[key] = merged(out[key], value) if isinstance(value, dict) and isinstance(out.get(key), dict) else value
    return out


def checked(config: dict[str, Any]) -> None:
    """What dpi.config.pipeline.resolve_config does with a merged config before the DAG is built."""
    check_config(apply_preset(config), CONFIG_SCHEMA)


BAD = {  # case: (patch of config.yaml, the message's start)
    "top-level typo": ({"sampels": 3}, "sampels: unknown key; did you mean 'samples'?"),
    "section typo": ({"method_param": {"dps": {}}}, "method_param: unknown key; did you mean 'method_params'?"),
    "render key typo": ({"render": {"sp": 4}}, "render.sp: unknown key; did you mean 'spp'?"),
    "problem key typo": ({"problem": {"env_hieght": 8}}, "problem.env_hieght: unknown key; did you mean 'env_height'?"),
    "resources key typo": ({"resources": {"sample": {"mem": 1}}}, "resources.sample.mem: unknown key"),
    "unknown method under method_params": ({"method_params": {"dpz": {}}},
                                           "method_params.dpz: unknown method; did you mean 'dps'?"),
    "unknown method listed": ({"methods": ["dps", "nonee"]},
                              "methods.1: 'nonee' is an unknown method; did you mean 'none'?"),
    "dps key typo": ({"method_params": {"dps": {"stepz": 10}}},
                     "method_params.dps.stepz: unknown DPSConfig setting; did you mean 'steps'?"),
    "classic key typo": ({"method_params": {"none": {"iteration": 10}}},
                         "method_params.none.iteration: unknown ClassicConfig setting; did you mean 'iterations'?"),
    "dps key on dip": ({"method_params": {"dip": {"steps": 10}}}, "method_params.dip.steps: unknown DIPConfig setting"),
    "sds key typo": ({"method_params": {"sds": {"tmax": 0.5}}},
                     "method_params.sds.tmax: unknown SDSConfig setting"),
    "steps 0": ({"method_params": {"dps": {"steps": 0}}}, "method_params.dps.steps: must be >= 2, got 0"),
    "steps -5": ({"method_params": {"dps": {"steps": -5}}}, "method_params.dps.steps: must be >= 2, got -5"),
    "steps 2.5": ({"method_params": {"dps": {"steps": 2.5}}}, "method_params.dps.steps: must be an integer, got 2.5"),
    "steps text": ({"method_params": {"dps": {"steps": "ten"}}},
                   "method_params.dps.steps: must be an integer, got 'ten'"),
    "a paper sampler section": ({"method_params": {"dps": {"paper": {"rho_schedule": "cubic"}}}},
                                "method_params.dps.paper: unknown DPSConfig setting"),
    "dps section key at the top": ({"method_params": {"dps": {"inner_steps": 3}}},
                                   "method_params.dps.inner_steps: unknown DPSConfig setting"),
    "level_every 0": ({"method_params": {"dps": {"proximal": {"level_every": 0}}}},
                      "method_params.dps.proximal.level_every: unknown ProximalConfig setting"),
    "inner_steps -3": ({"method_params": {"dps": {"proximal": {"inner_steps": -3}}}},
                       "method_params.dps.proximal.inner_steps: must be >= 1, got -3"),
    "odd transport spp": ({"method_params": {"dps": {"proximal": {"transport": {"spp": 3}}}}},
                          "method_params.dps.proximal.transport.spp: must be a multiple of 2"),
    "transport without pixels": ({"method_params": {"dps": {"proximal": {"transport": {"pixels": 0}}}}},
                                 "method_params.dps.proximal.transport.pixels: must be >= 1, got 0"),
    "negative refinement": ({"method_params": {"dps": {"refine": {"iterations": -1}}}},
                            "method_params.dps.refine.iterations: must be >= 0, got -1"),
    "env map of 100000 rows": ({"problem": {"env_height": 100000}},
                               "problem.env_height: must be <= 1024, got 100000"),
    "negative learning rate": ({"method_params": {"dps": {"lr_albedo": -0.1}}},
                               "method_params.dps.lr_albedo: must be > 0, got -0.1"),
    "nan learning rate": ({"method_params": {"smoothness": {"lr_env": float("nan")}}},
                          "method_params.smoothness.lr_env: must be a finite number, got nan"),
    "start noise above 1": ({"method_params": {"dps": {"proximal": {"start_noise": 1.5}}}},
                            "method_params.dps.proximal.start_noise: must be <= 1, got 1.5"),
    "sds map rate 0": ({"method_params": {"sds": {"lr_map": 0}}}, "method_params.sds.lr_map: must be > 0, got 0"),
    "zero views per step": ({"method_params": {"none": {"views_per_step": 0}}},
                            "method_params.none.views_per_step: must be >= 1, got 0"),
    "negative iterations": ({"method_params": {"dip": {"iterations": -1}}},
                            "method_params.dip.iterations: must be >= 0, got -1"),
    "dip channels text": ({"method_params": {"dip": {"channels": "many"}}},
                          "method_params.dip.channels: must be an integer, got 'many'"),
    "radiance_scale is the scene's": ({"method_params": {"dps": {"radiance_scale": 2.0}}},
                                      "method_params.dps.radiance_scale: unknown DPSConfig setting"),
    "method samples 0": ({"method_params": {"dps": {"samples": 0}}},
                         "method_params.dps.samples: must be >= 1, got 0"),
    "samples 0": ({"samples": 0}, "samples: must be >= 1, got 0"),
    "method entry not a mapping": ({"method_params": {"dps": 3}}, "method_params.dps: 3 is not of type 'object'"),
    "synthetic key typo": ({"synthetic": {"demo": {"shpe": "blob"}}},
                           "synthetic.demo.shpe: unknown SynthConfig setting; did you mean 'shape'?"),
    "synthetic prior martian": ({"synthetic": {"demo": {"prior": "martian"}}},
                                "synthetic.demo.prior: must be one of indoor, outdoor, got 'martian'"),
    "synthetic views 0": ({"synthetic": {"demo": {"views": 0}}}, "synthetic.demo.views: must be >= 1, got 0"),
    "preprocess key typo": ({"preprocess": {"sfm": {"matchr": "auto"}}},
                            "preprocess.sfm.matchr: unknown key; did you mean 'matcher'?"),
    "preprocess fraction above 1": ({"preprocess": {"sfm": {"min_registered_fraction": 1.5}}},
                                    "preprocess.sfm.min_registered_fraction: must be <= 1, got 1.5"),
    "geometry key typo": ({"preprocess": {"geometry": {"stero": False}}},
                          "preprocess.geometry.stero: unknown key; did you mean 'stereo'?"),
    "preprocess stage typo": ({"preprocess": {"uvs": {}}}, "preprocess.uvs: unknown key; did you mean 'uv'?"),
    "preset key typo": ({"presets": {"draft": {"rendr": {"spp": 4}}}},
                        "presets.draft.rendr: unknown key; did you mean 'render'?"),
    "unused preset bad value": ({"presets": {"paper": {"method_params": {"dps": {"steps": -1}}}}},
                                "presets.paper.method_params.dps.steps: must be >= 2, got -1"),
    "unknown prior family": ({"illumination_prior": {"family": "martian"}},
                             "illumination_prior.family: must be one of indoor, outdoor, got 'martian'"),
    "checkpoint of unknown family": ({"illumination_prior": {"checkpoints": {"martian": "m.pt"}}},
                                     "illumination_prior.checkpoints.martian: must be one of indoor, outdoor"),
    "prior training typo": ({"prior": {"stpes": 10}}, "prior.stpes: unknown TrainConfig setting; did you mean 'steps'?"),
    "prior family typo": ({"prior": {"indor": {"count": 10}}}, "prior.indor: must be one of indoor, outdoor"),
    "prior family's bad value": ({"prior": {"indoor": {"count": 0}}}, "prior.indoor.count: must be >= 1, got 0"),
    "negative agreement": ({"adaptive": {"agree_tolerance": -1}}, "adaptive.agree_tolerance: must be >= 0, got -1"),
    "zero threads": ({"threads": {"sample": 0}}, "threads.sample: must be >= 1, got 0"),
    "init views 0": ({"init": {"views_per_step": 0}}, "init.views_per_step: must be >= 1, got 0"),
    "scene with a slash": ({"scenes": ["a/b"]}, "scenes.0: 'a/b' is not a plain name"),
    "scene above the results": ({"scenes": [".."]}, "scenes.0: '..' is not a plain name"),
    "scene of the current folder": ({"scenes": ["."]}, "scenes.0: '.' is not a plain name"),
    "scene with braces": ({"scenes": ["a{b}"]}, "scenes.0: 'a{b}' is not a plain name"),
    "scene named too long": ({"scenes": ["a" * 65]}, "scenes.0: '" + "a" * 65 + "' is not a plain name"),
    "scene named like a run folder": ({"scenes": ["eval"]}, "scenes: 'eval' is the name of a folder results_dir keeps"),
    "scene named like the studies' folder": ({"scenes": ["benchmarks"]},
                                              "scenes: 'benchmarks' is the name of a folder results_dir keeps"),
    "results in the captures": ({"results_dir": "captures"}, "results_dir: captures is captures_dir"),
    "results inside a capture": ({"results_dir": "captures/demo/out"}, "results_dir: captures/demo/out lies inside"),
    "samples a float": ({"samples": 2.0}, "samples: 2.0 is not of type 'integer'"),
    "samples too many": ({"samples": 1000000000}, "samples: must be <= 256"),
    "evaluation spp too many": ({"evaluate": {"spp": 1000000000}}, "evaluate.spp: must be <= 4096"),
    "render spp a float": ({"render": {"spp": 16.0}}, "render.spp: 16.0 is not of type 'integer'"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_config_stops_with_the_key_path(case):
    """check_config raises one single-line ConfigError starting with the offending key's path."""
    patch, start = BAD[case]
    with pytest.raises(ConfigError) as info:
        checked(merged(SHIPPED, patch))
    message = str(info.value)
    assert message.startswith(start) and "\n" not in message, message


def test_unknown_preset_is_named():
    """`preset: fast` names the presets config.yaml defines."""
    with pytest.raises(ValueError, match="unknown preset 'fast'; config.yaml defines: default, draft, paper"):
        checked(merged(SHIPPED, {"preset": "fast"}))


def test_shipped_config_passes():
    """dpi's defaults are valid, every preset included."""
    checked(merged(SHIPPED, read_yaml(DEFAULT_CONFIG)))


def test_new_dataclass_fields_need_no_schema_change(monkeypatch):
    """method_params keys come from the method's dataclass: a field added to it is accepted at once."""
    from dataclasses import field

    from dpi.io.settings import settings
    from dpi.solve import methods
    from dpi.solve.classic import ClassicConfig

    @settings
    class Extended(ClassicConfig):
        temperature: float = 1.0
        optimize: object = field(default_factory=lambda: ClassicConfig().optimize)

    monkeypatch.setitem(methods.METHOD_CONFIGS, "none", Extended)
    checked(merged(SHIPPED, {"method_params": {"none": {"temperature": 0.5}}}))
    with pytest.raises(ConfigError, match=r"^method_params\.none\.temperature: must be a number, got 'hot'"):
        checked(merged(SHIPPED, {"method_params": {"none": {"temperature": "hot"}}}))


def test_sample_stage_rejects_a_bad_entry_before_reading_anything(tmp_path):
    """Called outside Snakemake (dpi sample), a bad method entry fails before any input is read or output written."""
    from dpi.stages import Pipeline, StageJob, sample_stage

    config = {**apply_preset(copy.deepcopy(SHIPPED)), "results_dir": str(tmp_path / "out"),
              "method_params": {"dps": {"steps": -5}}}
    with pytest.raises(ValueError, match=r"^steps: must be >= 2, got -5$"):
        sample_stage(StageJob(Pipeline(config), "s", "dps"))
    assert not (tmp_path / "out").exists()


def dry_run(workdir: Path, config: dict[str, Any]) -> subprocess.CompletedProcess:
    """`snakemake -n` of the repository's workflow with `config` in `workdir`."""
    write_config(workdir / "config.yaml", config)
    cmd = [str(SNAKEMAKE), "-s", str(REPO / "Snakefile"), "--directory", str(workdir), "--configfile",
           str(workdir / "config.yaml"), "-n", "--cores", "1"]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("case", ["steps -5", "unknown method under method_params"])
def test_snakemake_stops_before_the_dag_on_a_bad_config(tmp_path, case):
    """The workflow itself prints the one message and creates no results."""
    patch, start = BAD[case]
    proc = dry_run(tmp_path, merged(TINY_CONFIG, patch))
    assert proc.returncode != 0 and f"\n{start}" in proc.stdout + proc.stderr, proc.stderr[-2000:]
    assert not (tmp_path / "results").exists()


def test_snakemake_names_a_bad_scene_yaml_before_the_dag(tmp_path):
    """prior: martian in a capture's scene.yaml stops the dry run with the file's name (was a KeyError)."""
    root = make_capture(tmp_path / "captures" / "mine")
    (root / "scene.yaml").write_text("prior: martian\n")
    proc = dry_run(tmp_path, {"scenes": ["mine"], "methods": ["dps"]})
    assert proc.returncode != 0
    expected = "\ncaptures/mine/scene.yaml: prior must be one of indoor, outdoor, got 'martian'"
    assert expected in proc.stderr + proc.stdout
    assert not (tmp_path / "results").exists()
