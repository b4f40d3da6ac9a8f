# dpi: Diffusion Posterior Illumination as a Snakemake workflow.
#   snakemake --cores 2                         # the scenes and methods of ./config.yaml (as shipped: the demo)
#   snakemake --cores 2 --configfile my.yaml    # more settings, merged over ./config.yaml
# Settings: dpi's defaults (dpi/data/config.yaml), then config.yaml in the working directory (the
# top-level file of the checkout), then --configfile / --config, then the preset. rules/common.smk
# resolves them with dpi.config.pipeline.resolve_config, the same call the `dpi` command makes, so
# `dpi config` prints what this workflow runs with. (No `configfile:` directive: resolve_config owns
# the order, and a working directory without config.yaml runs on the defaults.)
# Every intermediate is a file under results/ (dpi.io.layout); unchanged stages are not rerun.


include: "rules/common.smk"
include: "rules/preprocess.smk"
include: "rules/inverse.smk"
include: "rules/evaluate.smk"
include: "rules/prior.smk"
include: "rules/export.smk"


rule all:
    input:
        LAYOUT.summary,
        all_figures(),
        LAYOUT.report_html,
        all_exports(),
        sample_plans(),  # a missing plan (more samples requested) is noticed even when the summary exists
    default_target: True
