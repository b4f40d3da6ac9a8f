"""Rule geometry: watertight surface carved from masks and cameras, cleaned up."""

from pathlib import Path

from dpi.io.logs import log_to
from dpi.preprocess.stages import geometry_stage

inputs = snakemake.input
with log_to(snakemake.log[0]):
    geometry_stage(inputs.capture, Path(snakemake.output.mesh).parent, snakemake.params.settings,
                   cameras_json=inputs.get("cameras_json"), masks_dir=inputs.get("masks_dir"), threads=snakemake.threads)
