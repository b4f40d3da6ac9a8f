"""Rule envmap_dataset: generate one family's procedural env-map dataset."""

from dpi import backend
from dpi.io.logs import log_to
from dpi.prior.procedural import make_envmap_dataset

with log_to(snakemake.log[0]):
    backend.mitsuba(threads=snakemake.threads)
    p = snakemake.params
    make_envmap_dataset(snakemake.wildcards.family, p.maps, p.height, snakemake.output[0], seed=p.seed)
