"""Rule sample: posterior sample k of one method for one scene."""

from pathlib import Path

from dpi.adaptive import AdaptiveConfig
from dpi.inverse_stages import SolveConfig, sample_stage
from dpi.io.logs import log_to

w = snakemake.wildcards
with log_to(snakemake.log[0]):
    sample_stage(snakemake.input.capture, Path(snakemake.input.init).parent, Path(snakemake.output.trace).parent,
                 w.scene, w.method, int(w.k), snakemake.params.method,
                 SolveConfig.from_config(snakemake.params.solve, snakemake.threads),
                 prior_checkpoint=snakemake.input.prior[0] if snakemake.input.prior else None,
                 adaptive=AdaptiveConfig.from_dict(snakemake.params.adaptive))
