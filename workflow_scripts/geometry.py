"""Rule geometry: watertight surface carved from masks and cameras, cleaned up."""

from dpi.logs import log_to
from dpi.preprocess.stages import geometry_stage

inputs = snakemake.input
with log_to(snakemake.log[0]):
    geometry_stage(inputs.capture, snakemake.output.mesh, snakemake.params.settings,
                   cameras_json=inputs.get("cameras"), masks_dir=inputs.get("masks"), threads=snakemake.threads)
