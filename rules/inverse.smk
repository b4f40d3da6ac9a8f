# Inverse rendering: path-traced initialisation, then N posterior-sample jobs per method.


rule init:
    input:
        unpack(scene_inputs),
    output:
        **INIT_FILES,
    params:
        init=config["init"],
        solve=solve_params(),
    threads: PIPELINE.threads("init")
    resources:
        **config["resources"]["init"],
    log:
        SCENE.log(INIT),
    benchmark:
        SCENE.benchmark(INIT)
    script:
        "../workflow_scripts/stage.py"


rule sample:
    input:
        unpack(scene_inputs),
        init=INIT_FILES["trace"],
        prior=method_prior,
    output:
        **SAMPLE,
    params:
        method=lambda w: PIPELINE.method_params(w.method),
        solve=solve_params(),
        adaptive=lambda w: adaptive_params("diffuse_") if REGISTRY[w.method].adaptive_steps else {},
    threads: PIPELINE.threads("sample")
    resources:
        **config["resources"]["sample"],
    log:
        SCENE.log("{method}", "{k}"),
    benchmark:
        SCENE.benchmark("{method}", "{k}")
    script:
        "../workflow_scripts/stage.py"


# The sample stop rule (dpi.solve.adaptive): once a method's first samples exist, decide how many it
# draws in all. Only methods with more than dpi.solve.adaptive.MIN_SAMPLES samples wait for it.
checkpoint sample_plan:
    input:
        lambda w: [LAYOUT.scene(w.scene).sample_files(w.method, k)["env"] for k in range(MIN_SAMPLES)],
    output:
        SCENE.plan("{method}"),
    params:
        samples=lambda w: PIPELINE.samples(w.method),
        adaptive=adaptive_params("sample_stop", "agree_tolerance"),
    log:
        SCENE.log("{method}", "plan"),
    script:
        "../workflow_scripts/stage.py"
