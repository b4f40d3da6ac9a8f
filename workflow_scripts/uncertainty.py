"""Rule uncertainty: per method, the per-texel spread of its samples' env maps and albedo (EXR), and their figure."""

from dpi.logs import log_to
from dpi.stages import uncertainty_stage

with log_to(snakemake.log[0]):
    uncertainty_stage(snakemake.params.scene, snakemake.params.rows, snakemake.output.figure)
