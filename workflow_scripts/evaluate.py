"""Rule evaluate: metrics of one posterior sample."""

from pathlib import Path

from dpi.logs import log_to
from dpi.stages import SolveSettings, evaluate_stage

w = snakemake.wildcards
with log_to(snakemake.log[0]):
    evaluate_stage(snakemake.input.capture, Path(snakemake.input.sample).parent, snakemake.output[0], w.scene,
                   w.method, int(w.k), snakemake.params.spp,
                   SolveSettings.from_config(snakemake.params.solve, snakemake.threads))
