# Export: each scene's decompositions as one glTF binary and one USD stage, every sample of every method a
# variant (dpi.stages.export), with the samples' env maps beside them.


rule export:
    input:
        unpack(scene_inputs),
        lambda w: [LAYOUT.scene(w.scene).sample_files(m, k)[part] for m, folders in sample_rows(w.scene)
                   for k in range(len(folders)) for part in ("env", "albedo", "roughness", "metallic")],
        lambda w: [path for m in SPREAD_METHODS for path in LAYOUT.scene(w.scene).uncertainty(m).values()],
        lambda w: sample_plans([w.scene]),
        init=INIT_FILES["trace"],
    output:
        glb=SCENE.export_asset("glb"),
        usd=SCENE.export_asset("usda"),
    params:
        stage_args=lambda w: [sample_rows(w.scene)],
    log:
        SCENE.log("export"),
    benchmark:
        SCENE.benchmark("export")
    script:
        "../workflow_scripts/stage.py"
