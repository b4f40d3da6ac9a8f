"""Rule train_prior: train (resuming) a prior on a dataset folder and export its EMA weights."""

from dpi import backend
from dpi.logs import log_to
from dpi.prior.train import TrainConfig, train_and_export
from dpi.prior.unet import SMALL_CONFIGS

with log_to(snakemake.log[0]):
    backend.set_threads(snakemake.threads)
    s = dict(snakemake.params.settings)
    cfg = TrainConfig(family=snakemake.wildcards.family, data_dir=snakemake.input[0], out=snakemake.params.checkpoint,
                      model=SMALL_CONFIGS[s.pop("model")], **s)
    train_and_export(cfg, snakemake.output[0])
