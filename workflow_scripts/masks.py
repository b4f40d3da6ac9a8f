"""Rule masks: foreground masks of a capture's views (GrabCut with a sparse-point prior, or keying)."""

from dpi.capture import CaptureError
from dpi.io.logs import log_to
from dpi.preprocess.stages import masks_stage

inputs = snakemake.input
with log_to(snakemake.log[0], one_line=(CaptureError,)):
    masks_stage(inputs.capture, snakemake.output[0], snakemake.params.settings,
                cameras_json=inputs.get("cameras_json"), points_ply=inputs.get("points_ply"), threads=snakemake.threads)
