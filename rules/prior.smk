# Diffusion prior: procedural env-map datasets, then DDPM training on them. Settings: the config's
# `prior:` section (dpi.prior.train.PriorJobConfig and TrainConfig fields; a family's own mapping
# overrides them), read through dpi.config.pipeline.Pipeline.prior_job.


wildcard_constraints:
    family="|".join(PRIORS),


rule envmap_dataset:
    output:
        directory(LAYOUT.prior_data("{family}")),
    params:
        maps=lambda w: PIPELINE.prior_job(w.family).count,
        height=lambda w: PIPELINE.prior_job(w.family).data_height,
        seed=lambda w: PIPELINE.prior_job(w.family).train_config().seed,
    threads: 1
    log:
        LAYOUT.prior_log("{family}", "envmap_dataset"),
    script:
        "../workflow_scripts/stage.py"


rule train_prior:
    input:
        LAYOUT.prior_data("{family}"),
    output:
        LAYOUT.prior_model("{family}"),
    params:
        job=lambda w: plain(PIPELINE.prior_job(w.family)),
    threads: lambda w: PIPELINE.prior_job(w.family).threads
    log:
        LAYOUT.prior_log("{family}", "train_prior"),
    benchmark:
        LAYOUT.prior_benchmark("{family}", "train_prior")
    script:
        "../workflow_scripts/stage.py"
