"""Rule capture: validate the capture folder once and write capture.json."""

from dpi.logs import log_to
from dpi.stages import capture_stage

with log_to(snakemake.log[0]):
    capture_stage(snakemake.params.capture, snakemake.output[0])
