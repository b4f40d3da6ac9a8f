"""Rule poses: camera poses of a photo capture by structure from motion (COLMAP)."""

from pathlib import Path

from dpi.capture import CaptureError
from dpi.io.logs import log_to
from dpi.preprocess.stages import poses_stage

with log_to(snakemake.log[0], one_line=(CaptureError,)):
    poses_stage(snakemake.input.capture, Path(snakemake.output.cameras).parent, snakemake.params.settings,
                threads=snakemake.threads)
