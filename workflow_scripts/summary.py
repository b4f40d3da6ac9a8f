"""Rule summary: aggregate every per-sample metric file into summary.csv."""

from dpi.logs import log_to
from dpi.stages import summary_stage

with log_to(snakemake.log[0]):
    summary_stage([*snakemake.input.evaluations, *snakemake.input.planned], snakemake.output.summary,
                  snakemake.output.samples)
