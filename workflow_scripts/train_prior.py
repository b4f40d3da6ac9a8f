"""Rule train_prior: train (resuming) a prior on a dataset folder and export its EMA weights."""

from dpi import backend
from dpi.io.logs import log_to
from dpi.prior.train import PriorJobConfig, train_and_export

with log_to(snakemake.log[0]):
    backend.set_threads(snakemake.threads)
    job = PriorJobConfig(**snakemake.params.job)
    train_and_export(job.train_config(), snakemake.wildcards.family, snakemake.input[0], snakemake.params.checkpoint,
                     snakemake.output[0])
