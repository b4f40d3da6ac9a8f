"""Rule envmap_figure: a PNG grid of each method's env-map samples next to the ground truth."""

from dpi.inverse_stages import envmap_figure_stage
from dpi.io.logs import log_to

with log_to(snakemake.log[0]):
    envmap_figure_stage(snakemake.input.capture, snakemake.params.rows, snakemake.output[0])
