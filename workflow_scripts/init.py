"""Rule init: path-traced initialisation of one scene."""

from pathlib import Path

from dpi.logs import log_to
from dpi.stages import SolveSettings, init_stage

with log_to(snakemake.log[0]):
    init_stage(snakemake.input.capture, Path(snakemake.output.trace).parent, snakemake.wildcards.scene,
               snakemake.params.init, SolveSettings.from_config(snakemake.params.solve, snakemake.threads))
