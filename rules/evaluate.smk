# Evaluation: metrics per sample, then one summary table over samples, methods and scenes.


rule evaluate:
    input:
        capture=f"{RESULTS}/{{scene}}/capture.json",
        sample=rules.sample.output.trace,
        prior=scene_prior,
    output:
        f"{RESULTS}/{{scene}}/eval/{{method}}/{{k}}.json",
    params:
        spp=config["evaluate"]["spp"],
        solve=solve_params(),
    threads: config["threads"]["evaluate"]
    resources:
        mem_mb=config["resources"]["evaluate"]["mem_mb"],
        runtime=config["resources"]["evaluate"]["runtime"],
    log:
        f"{RESULTS}/{{scene}}/logs/eval/{{method}}/{{k}}.log",
    script:
        "../workflow_scripts/evaluate.py"


rule evaluate_init:
    input:
        capture=f"{RESULTS}/{{scene}}/capture.json",
        sample=rules.init.output.log,
        prior=scene_prior,
    output:
        f"{RESULTS}/{{scene}}/eval/init/0.json",
    params:
        spp=config["evaluate"]["spp"],
        solve=solve_params(),
    threads: config["threads"]["evaluate"]
    resources:
        mem_mb=config["resources"]["evaluate"]["mem_mb"],
        runtime=config["resources"]["evaluate"]["runtime"],
    log:
        f"{RESULTS}/{{scene}}/logs/eval/init.log",
    script:
        "../workflow_scripts/evaluate.py"


rule summary:
    input:
        evaluations=fixed_evaluations(),
        planned=planned_evaluations,
        plans=sample_plans(),
    output:
        summary=report(f"{RESULTS}/eval/summary.csv", caption="../report/summary.rst", category="Metrics"),
        samples=f"{RESULTS}/eval/samples.csv",
    log:
        f"{RESULTS}/logs/summary.log",
    script:
        "../workflow_scripts/summary.py"


rule envmap_figure:
    input:
        lambda w: [path for _, paths in sample_envmaps(w.scene) for path in paths],
        lambda w: sample_plans([w.scene]),
    output:
        report(f"{RESULTS}/{{scene}}/eval/envmaps.png", caption="../report/envmaps.rst", category="Env maps"),
    params:
        rows=lambda w: sample_envmaps(w.scene),
        reference=lambda w: ground_truth_envmap(w.scene),
    log:
        f"{RESULTS}/{{scene}}/logs/envmap_figure.log",
    script:
        "../workflow_scripts/envmap_figure.py"


rule report:
    input:
        summary=rules.summary.output.summary,
        evaluations=fixed_evaluations(),
        planned=planned_evaluations,
        plans=sample_plans(),
    output:
        html=report(f"{RESULTS}/report.html", caption="../report/report.rst", category="Report"),
        figures=directory(f"{RESULTS}/report"),
    params:
        results=RESULTS,
        spp=config["evaluate"]["spp"],
        solve=solve_params(),
    threads: config["threads"]["evaluate"]
    log:
        f"{RESULTS}/logs/report.log",
    script:
        "../workflow_scripts/report.py"
