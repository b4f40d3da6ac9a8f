"""Rule summary: aggregate every per-sample metric file into summary.csv."""

from dpi.inverse_stages import summary_stage
from dpi.io.logs import log_to

with log_to(snakemake.log[0]):
    summary_stage([*snakemake.input.evaluations, *snakemake.input.planned], snakemake.output.summary,
                  snakemake.output.samples)
