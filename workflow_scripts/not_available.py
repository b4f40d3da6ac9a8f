"""Placeholder rules (poses, masks, surface, UVs) for captures that do not provide these inputs."""

from dpi.logs import log_to

with log_to(snakemake.log[0]):
    raise RuntimeError(
        f"{snakemake.input[0]}: this capture needs the {snakemake.params.stage} stage, which dpi does not "
        "implement yet; provide the input in the capture folder (see README, 'Your own capture')."
    )
