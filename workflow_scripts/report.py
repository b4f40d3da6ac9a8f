"""Rule report: the HTML report over every scene and method (report.html and its PNGs)."""

from dpi.logs import log_to
from dpi.report import build_report
from dpi.stages import SolveSettings

with log_to(snakemake.log[0]):
    build_report(snakemake.params.results, snakemake.output.html, snakemake.output.figures, snakemake.params.spp,
                 SolveSettings.from_config(snakemake.params.solve, snakemake.threads))
