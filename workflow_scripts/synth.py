"""Rule synth_capture: render a synthetic capture declared under the config's `synthetic:`."""

from pathlib import Path

from dpi.io.logs import log_to
from dpi.synth.capture import SynthConfig, make_synthetic_capture

with log_to(snakemake.log[0]):
    make_synthetic_capture(Path(snakemake.output[0]).parent, SynthConfig.from_dict(snakemake.params.synth),
                           threads=snakemake.threads, overwrite=True)
