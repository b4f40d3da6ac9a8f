"""Stages of rules/prior.smk: a family's procedural env-map dataset, then its diffusion prior trained on it,
with the settings of config `prior:` (dpi.config.pipeline.Pipeline.prior_job)."""

from __future__ import annotations

from dpi.prior.procedural import make_envmap_dataset
from dpi.prior.train import train_and_export
from dpi.render import backend
from dpi.stages.job import StageJob


def envmap_dataset_stage(job: StageJob) -> dict:
    """The family's procedural maps into its dataset folder; returns the dataset's manifest."""
    backend.mitsuba(threads=job.threads)
    settings = job.pipeline.prior_job(job.family)
    layout = job.pipeline.layout
    return make_envmap_dataset(job.family, settings.count, settings.data_height, layout.prior_data(job.family),
                               seed=settings.train_config().seed, progress=job.progress)


def train_prior_stage(job: StageJob) -> dict:
    """Train the family's prior on its dataset (resuming from its working checkpoint) and export the model."""
    backend.set_threads(job.threads)
    layout = job.pipeline.layout
    return train_and_export(job.pipeline.prior_job(job.family).train_config(), job.family,
                            layout.prior_data(job.family), layout.prior_checkpoint(job.family),
                            layout.prior_model(job.family))
