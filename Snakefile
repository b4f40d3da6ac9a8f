# dpi: Diffusion Posterior Illumination as a Snakemake workflow.
#   snakemake --cores 2                         # the demo (config.yaml)
#   snakemake --cores 2 --configfile my.yaml    # your own scenes
# Every intermediate is a file under results/; unchanged stages are not rerun.

configfile: "config.yaml"


include: "rules/common.smk"
include: "rules/preprocess.smk"
include: "rules/inverse.smk"
include: "rules/evaluate.smk"
include: "rules/prior.smk"


rule all:
    input:
        f"{RESULTS}/eval/summary.csv",
        all_figures(),
        f"{RESULTS}/report.html",
        sample_plans(),  # a missing plan (more samples requested) is noticed even when the summary exists
    default_target: True
