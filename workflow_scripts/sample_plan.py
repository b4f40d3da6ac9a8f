"""Checkpoint sample_plan: how many samples a method draws, from its first samples (the stop rule)."""

from dpi.adaptive import AdaptiveConfig, sample_plan_stage
from dpi.io.logs import log_to

with log_to(snakemake.log[0]):
    plan = sample_plan_stage(list(snakemake.input), snakemake.output[0], snakemake.params.samples,
                             AdaptiveConfig.from_dict(snakemake.params.adaptive))
    print(f"adaptive: {plan['reason']}")
