"""Rules evaluate and evaluate_init: metrics of one posterior sample (or of the initialisation) and its
held-out re-renders."""

from pathlib import Path

from dpi.inverse_stages import SolveConfig, evaluate_stage
from dpi.io.logs import log_to
from dpi.layout import INIT

w = snakemake.wildcards
method, k = getattr(w, "method", INIT), int(getattr(w, "k", 0))
with log_to(snakemake.log[0]):
    evaluate_stage(snakemake.input.capture, Path(snakemake.input.sample).parent, snakemake.output.metrics, w.scene,
                   method, k, snakemake.params.spp,
                   SolveConfig.from_config(snakemake.params.solve, snakemake.threads), snakemake.input.prior,
                   views_dir=snakemake.output.views, references=snakemake.params.references)
