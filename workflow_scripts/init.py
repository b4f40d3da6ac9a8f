"""Rule init: path-traced initialisation of one scene."""

from pathlib import Path

from dpi.inverse_stages import SolveConfig, init_stage
from dpi.io.logs import log_to

with log_to(snakemake.log[0]):
    init_stage(snakemake.input.capture, Path(snakemake.output.trace).parent, snakemake.wildcards.scene,
               snakemake.params.init, SolveConfig.from_config(snakemake.params.solve, snakemake.threads))
