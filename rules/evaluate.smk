# Evaluation: metrics per sample (and its held-out re-renders), then one summary table over samples,
# methods and scenes, the env-map grid of each scene, and the report drawn from them.


rule evaluate:
    input:
        capture=SCENE.capture_json,
        sample=SAMPLE["trace"],
        prior=scene_prior,
    output:
        metrics=SCENE.evaluation("{method}", "{k}"),
        views=directory(SCENE.evaluation_views("{method}", "{k}")),
    params:
        spp=config["evaluate"]["spp"],
        references=config["evaluate"]["reference_panoramas"],
        solve=solve_params(),
    threads: PIPELINE.threads("evaluate")
    resources:
        **config["resources"]["evaluate"],
    log:
        SCENE.evaluation_log("{method}", "{k}"),
    script:
        "../workflow_scripts/stage.py"


use rule evaluate as evaluate_init with:
    input:
        capture=SCENE.capture_json,
        sample=INIT_FILES["trace"],
        prior=scene_prior,
    output:
        metrics=SCENE.evaluation(INIT),
        views=directory(SCENE.evaluation_views(INIT)),
    log:
        SCENE.evaluation_log(INIT),


rule summary:
    input:
        evaluations=fixed_evaluations(),
        planned=planned_evaluations,
        plans=sample_plans(),
    output:
        summary=report(LAYOUT.summary, caption="../report/summary.rst", category="Metrics"),
        samples=LAYOUT.samples_table,
    params:
        stage_args=lambda w, input: [[*input.evaluations, *input.planned]],
    log:
        LAYOUT.log("summary"),
    script:
        "../workflow_scripts/stage.py"


rule envmap_figure:
    input:
        lambda w: [path for _, paths in sample_envmaps(w.scene) for path in paths],
        lambda w: sample_plans([w.scene]),
        capture=SCENE.capture_json,
    output:
        report(SCENE.envmap_figure, caption="../report/envmaps.rst", category="Env maps"),
    params:
        stage_args=lambda w: [sample_envmaps(w.scene)],
    log:
        SCENE.log("envmap_figure"),
    script:
        "../workflow_scripts/stage.py"


rule uncertainty:
    input:
        lambda w: [LAYOUT.scene(w.scene).sample_files(m, k)[part] for m, folders in sample_folders(w.scene)
                   for k in range(len(folders)) for part in ("env", "albedo")],
        lambda w: sample_plans([w.scene]),
    output:
        *[path for m in SPREAD_METHODS for path in SCENE.uncertainty(m).values()],
        figure=report(SCENE.uncertainty_figure, caption="../report/uncertainty.rst", category="Env maps"),
    params:
        stage_args=lambda w: [sample_folders(w.scene)],
    log:
        SCENE.log("uncertainty"),
    script:
        "../workflow_scripts/stage.py"


rule report:
    input:
        summary=rules.summary.output.summary,
        evaluations=fixed_evaluations(),
        planned=planned_evaluations,
        plans=sample_plans(),
        figures=all_figures(),
        exports=all_exports(),  # the 3D view embeds each scene's glTF asset
    output:
        html=report(LAYOUT.report_html, caption="../report/report.rst", category="Report"),
        figures=directory(LAYOUT.report_figures),
    log:
        LAYOUT.log("report"),
    script:
        "../workflow_scripts/stage.py"
