"""Rule report: the HTML report over every scene and method (report.html and its PNGs)."""

from pathlib import Path

from dpi.evaluation.report import build_report
from dpi.io.logs import log_to
from dpi.layout import Layout

with log_to(snakemake.log[0]):
    layout = Layout(**{k: Path(v) for k, v in snakemake.params.layout.items()})
    build_report(layout, snakemake.output.html, snakemake.output.figures)
