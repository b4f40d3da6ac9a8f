"""The stages layer: every stage function of the workflow, one module per rules/*.smk, each taking one
`StageJob`. The Snakemake rules, the `dpi` command and the study engine build that record and call these
functions; rules/common.smk imports this module only, so what the rules need of the pipeline is named here.

Names load lazily (PEP 562): a rule's job imports only the module of its own stage."""

from importlib import import_module
from typing import Any

PROVIDERS = {
    "dpi.solve.adaptive": ("MIN_SAMPLES", "stop_rule_applies"),
    "dpi.capture": ("PRIORS", "derived_inputs"),
    "dpi.io.lock": ("check_unlocked", "lock_results"),
    "dpi.io.atomic": ("check_no_links",),
    "dpi.io.layout": ("ENV_FILE", "INIT"),
    "dpi.config.pipeline": ("Pipeline", "load_pipeline", "plain", "resolve_config"),
    "dpi.solve.methods": ("METHODS", "REGISTRY"),
    "dpi.stages.job": ("StageJob", "rule_job"),
    "dpi.stages.preprocess": ("STAGES", "capture_stage", "geometry_stage", "masks_stage", "needed_stages",
                              "poses_stage", "preprocess_scene", "stage_inputs", "synth_capture_stage", "uv_stage"),
    "dpi.stages.inverse": ("init_stage", "load_problem", "sample_plan_stage", "sample_stage"),
    "dpi.stages.evaluate": ("envmap_figure_stage", "evaluate_stage", "report_stage", "summary_stage",
                            "uncertainty_stage"),
    "dpi.stages.prior": ("envmap_dataset_stage", "train_prior_stage"),
    "dpi.stages.export": ("export_stage",),
}
"""each public name and the module that defines it"""
_MODULE = {name: module for module, names in PROVIDERS.items() for name in names}

RULES = {"synth_capture": "synth_capture_stage", "capture": "capture_stage", "poses": "poses_stage",
         "masks": "masks_stage", "geometry": "geometry_stage", "uv": "uv_stage", "init": "init_stage",
         "sample": "sample_stage", "sample_plan": "sample_plan_stage", "evaluate": "evaluate_stage",
         "evaluate_init": "evaluate_stage", "summary": "summary_stage", "envmap_figure": "envmap_figure_stage",
         "uncertainty": "uncertainty_stage", "report": "report_stage", "envmap_dataset": "envmap_dataset_stage",
         "train_prior": "train_prior_stage", "export": "export_stage"}
"""each Snakemake rule's stage function, by name (workflow_scripts/stage.py runs it on the rule's job record)"""

__all__ = sorted(["RULES", "rule_stage", *_MODULE])


def rule_stage(rule: str) -> Any:
    """The stage function of a Snakemake rule."""
    return __getattr__(RULES[rule])


def __getattr__(name: str) -> Any:
    if name not in _MODULE:
        raise AttributeError(f"module 'dpi.stages' has no attribute {name!r}")
    return getattr(import_module(_MODULE[name]), name)
