"""Rule capture: validate the capture folder once and write capture.json (a bad capture: one line, no traceback)."""

from dpi.capture import CaptureError
from dpi.io.logs import log_to
from dpi.preprocess.stages import capture_stage

with log_to(snakemake.log[0], one_line=(CaptureError,)):
    capture_stage(snakemake.params.capture, snakemake.output[0])
