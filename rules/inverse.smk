# Inverse rendering: path-traced initialisation, then N posterior-sample jobs per method.


rule init:
    input:
        unpack(scene_inputs),
    output:
        env=f"{RESULTS}/{{scene}}/init/envmap.exr",
        albedo=f"{RESULTS}/{{scene}}/init/albedo.exr",
        roughness=f"{RESULTS}/{{scene}}/init/roughness.exr",
        metallic=f"{RESULTS}/{{scene}}/init/metallic.exr",
        log=f"{RESULTS}/{{scene}}/init/log.json",
    params:
        init=config["init"],
        solve=solve_params(),
    threads: config["threads"]["init"]
    resources:
        mem_mb=config["resources"]["init"]["mem_mb"],
        runtime=config["resources"]["init"]["runtime"],
        gpu=config["resources"]["init"]["gpu"],
    log:
        f"{RESULTS}/{{scene}}/logs/init.log",
    benchmark:
        f"{RESULTS}/{{scene}}/benchmarks/init.tsv"
    script:
        "../workflow_scripts/init.py"


rule sample:
    input:
        unpack(scene_inputs),
        init=rules.init.output.log,
        prior=prior_checkpoint,
    output:
        env=f"{RESULTS}/{{scene}}/{{method}}/{{k}}/envmap.exr",
        albedo=f"{RESULTS}/{{scene}}/{{method}}/{{k}}/albedo.exr",
        roughness=f"{RESULTS}/{{scene}}/{{method}}/{{k}}/roughness.exr",
        metallic=f"{RESULTS}/{{scene}}/{{method}}/{{k}}/metallic.exr",
        trace=f"{RESULTS}/{{scene}}/{{method}}/{{k}}/trace.json",
    params:
        method=lambda w: method_params(w.method),
        solve=solve_params(),
        adaptive=lambda w: adaptive_params("diffuse_") if w.method == "dps" else {},
    threads: config["threads"]["sample"]
    resources:
        mem_mb=config["resources"]["sample"]["mem_mb"],
        runtime=config["resources"]["sample"]["runtime"],
        gpu=config["resources"]["sample"]["gpu"],
    log:
        f"{RESULTS}/{{scene}}/logs/{{method}}/{{k}}.log",
    benchmark:
        f"{RESULTS}/{{scene}}/benchmarks/{{method}}/{{k}}.tsv"
    script:
        "../workflow_scripts/sample.py"


# The sample stop rule (dpi.adaptive): once a method's first samples exist, decide how many it
# draws in all. Only methods with more than adaptive.min_samples samples wait for it.
checkpoint sample_plan:
    input:
        lambda w: [f"{RESULTS}/{w.scene}/{w.method}/{k}/envmap.exr" for k in range(ADAPTIVE_CONFIG.min_samples)],
    output:
        f"{RESULTS}/{{scene}}/{{method}}/plan.json",
    params:
        samples=lambda w: method_samples(w.method),
        adaptive=adaptive_params("sample_stop", "min_samples", "agree_tolerance"),
    log:
        f"{RESULTS}/{{scene}}/logs/{{method}}/plan.log",
    script:
        "../workflow_scripts/sample_plan.py"
