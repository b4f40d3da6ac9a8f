# dpi: Diffusion Posterior Illumination as a Snakemake workflow.
#   snakemake --cores 2                         # the demo (dpi's defaults, dpi/data/config.yaml)
#   snakemake --cores 2 --configfile my.yaml    # your own scenes, merged over the defaults
# A config.yaml in the working directory is merged over the defaults too (dpi.pipeline).
# Every intermediate is a file under results/ (dpi.layout); unchanged stages are not rerun.


include: "rules/common.smk"
include: "rules/preprocess.smk"
include: "rules/inverse.smk"
include: "rules/evaluate.smk"
include: "rules/prior.smk"


rule all:
    input:
        LAYOUT.summary,
        all_figures(),
        LAYOUT.report_html,
        sample_plans(),  # a missing plan (more samples requested) is noticed even when the summary exists
    default_target: True
