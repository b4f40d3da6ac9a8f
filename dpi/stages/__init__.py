"""The stages layer: every stage function of the workflow, one module per rules/*.smk, each taking one
`StageJob`. The Snakemake rules, the `dpi` command and the study engine build that record and call these
functions; rules/common.smk imports this module only, so what the rules need of the pipeline is named here."""

from dpi.adaptive import MIN_SAMPLES, stop_rule_applies
from dpi.capture import PRIORS, derived_inputs
from dpi.io.lock import lock_results
from dpi.layout import INIT
from dpi.pipeline import Pipeline, load_pipeline, plain, resolve_config
from dpi.solve.methods import METHODS, REGISTRY
from dpi.stages.evaluate import envmap_figure_stage, evaluate_stage, report_stage, summary_stage, uncertainty_stage
from dpi.stages.export import export_stage
from dpi.stages.inverse import init_stage, load_problem, sample_plan_stage, sample_stage
from dpi.stages.job import StageJob, rule_job
from dpi.stages.preprocess import (STAGES, capture_stage, geometry_stage, masks_stage, needed_stages, poses_stage,
                                   preprocess_scene, stage_inputs, synth_capture_stage, uv_stage)
from dpi.stages.prior import envmap_dataset_stage, train_prior_stage

RULES = {"synth_capture": synth_capture_stage, "capture": capture_stage, "poses": poses_stage,
         "masks": masks_stage, "geometry": geometry_stage, "uv": uv_stage, "init": init_stage,
         "sample": sample_stage, "sample_plan": sample_plan_stage, "evaluate": evaluate_stage,
         "evaluate_init": evaluate_stage, "summary": summary_stage, "envmap_figure": envmap_figure_stage,
         "uncertainty": uncertainty_stage, "report": report_stage, "envmap_dataset": envmap_dataset_stage,
         "train_prior": train_prior_stage, "export": export_stage}
"""each Snakemake rule's stage function (workflow_scripts/stage.py runs it on the rule's job record)"""

__all__ = ["INIT", "METHODS", "MIN_SAMPLES", "PRIORS", "Pipeline", "REGISTRY", "RULES", "STAGES", "StageJob",
           "capture_stage", "derived_inputs", "envmap_dataset_stage", "envmap_figure_stage", "evaluate_stage",
           "export_stage", "geometry_stage", "init_stage", "load_pipeline", "load_problem", "lock_results",
           "masks_stage", "needed_stages", "plain", "poses_stage", "preprocess_scene", "report_stage",
           "resolve_config", "rule_job", "sample_plan_stage", "sample_stage", "stage_inputs", "stop_rule_applies",
           "summary_stage", "synth_capture_stage", "train_prior_stage", "uncertainty_stage", "uv_stage"]
