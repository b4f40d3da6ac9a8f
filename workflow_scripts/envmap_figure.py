"""Rule envmap_figure: a PNG grid of each method's env-map samples next to the ground truth."""

from pathlib import Path

from dpi.figures import envmap_grid
from dpi.logs import log_to

with log_to(snakemake.log[0]):
    rows = [(method, [Path(p) for p in files]) for method, files in snakemake.params.rows]
    reference = snakemake.params.reference
    envmap_grid(rows, snakemake.output[0], Path(reference) if reference else None)
