"""Rule uncertainty: per method, the per-texel spread of its samples' env maps and albedo (EXR), and their figure."""

from dpi.inverse_stages import uncertainty_stage
from dpi.io.logs import log_to

with log_to(snakemake.log[0]):
    uncertainty_stage(snakemake.params.scene, snakemake.params.rows, snakemake.output.figure)
