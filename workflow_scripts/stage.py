"""Every rule's script: the rule's stage function (dpi.stages.RULES) on the rule's job record, with the
rule's `stage_args` param when it has one, logged to the rule's log (a capture or output-path error as its one line).
Every output of the rule under results_dir is checked first to reach it through no link (dpi.io.atomic.inside_results;
the one rule writing elsewhere renders a synthetic capture into captures_dir)."""

from pathlib import Path

from dpi.capture import CaptureError
from dpi.io.atomic import OutputError, inside_results
from dpi.io.logs import log_to
from dpi.stages import rule_job, rule_stage

with log_to(snakemake.log[0], one_line=(CaptureError, OutputError)):
    job = rule_job(snakemake)
    results = job.pipeline.layout.results
    for output in snakemake.output:
        if Path(output).absolute().is_relative_to(Path(results).absolute()):
            inside_results(output, results)
    rule_stage(snakemake.rule)(job, *snakemake.params.get("stage_args", ()))
