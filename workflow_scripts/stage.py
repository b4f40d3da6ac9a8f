"""Every rule's script: the rule's stage function (dpi.stages.RULES) on the rule's job record, with the
rule's `stage_args` param when it has one, logged to the rule's log (a capture or output-path error as its one line;
a link inside results_dir is refused when the workflow is read, rules/common.smk)."""

from dpi.capture import CaptureError
from dpi.io.atomic import OutputError
from dpi.io.logs import log_to
from dpi.stages import rule_job, rule_stage

with log_to(snakemake.log[0], one_line=(CaptureError, OutputError)):
    rule_stage(snakemake.rule)(rule_job(snakemake), *snakemake.params.get("stage_args", ()))
