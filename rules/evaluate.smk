# Evaluation: metrics per sample, then one summary table over samples, methods and scenes.


rule evaluate:
    input:
        capture=f"{RESULTS}/{{scene}}/capture.json",
        sample=rules.sample.output.trace,
    output:
        f"{RESULTS}/{{scene}}/eval/{{method}}/{{k}}.json",
    params:
        spp=config["evaluate"]["spp"],
        solve=solve_params(),
    threads: config["threads"]["evaluate"]
    log:
        f"{RESULTS}/{{scene}}/logs/eval/{{method}}/{{k}}.log",
    script:
        "../workflow_scripts/evaluate.py"


rule summary:
    input:
        all_evaluations(),
    output:
        summary=report(f"{RESULTS}/eval/summary.csv", caption="../report/summary.rst", category="Metrics"),
        samples=f"{RESULTS}/eval/samples.csv",
    log:
        f"{RESULTS}/logs/summary.log",
    script:
        "../workflow_scripts/summary.py"
