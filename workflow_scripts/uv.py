"""Rule uv: UV atlas (xatlas) of the reconstructed mesh or of the capture's mesh without UVs."""

from pathlib import Path

from dpi.io.logs import log_to
from dpi.preprocess.stages import uv_stage

with log_to(snakemake.log[0]):
    uv_stage(snakemake.input.capture, Path(snakemake.output.mesh_uv).parent, snakemake.params.settings,
             mesh=snakemake.input.get("mesh"))
