# Capture preparation: synthetic captures, validation, and the stages that derive missing inputs.


rule synth_capture:
    output:
        LAYOUT.synth_marker("{scene}"),
    params:
        synth=lambda w: plain(PIPELINE.synth_settings(w.scene)),
    threads: PIPELINE.threads("synth")
    log:
        SCENE.log("synth"),
    script:
        "../workflow_scripts/stage.py"


rule capture:
    input:
        capture_files,
    output:
        SCENE.capture_json,
    log:
        SCENE.log("capture"),
    script:
        "../workflow_scripts/stage.py"


# Stages that derive what a photo capture lacks (dpi.preprocess). Each is scheduled only when the
# capture does not give its output, and reads only what the stages before it derived
# (dpi.stages.preprocess: needed_stages, stage_inputs; dpi.capture.derived_inputs for init and the
# methods): poses (COLMAP) -> masks (GrabCut / keying) -> geometry (carved SDF + cleanup) -> uv (xatlas).


def stage_inputs_of(stage):
    """Input function: the derived files a preprocessing stage reads, as its stage function names them."""
    return lambda w: stage_inputs(stage, given(w.scene), scene_layout(w))


rule poses:
    input:
        capture=SCENE.capture_json,
    output:
        **SCENE.poses,
    params:
        settings=config["preprocess"]["sfm"],
    threads: PIPELINE.threads("preprocess")
    resources:
        **config["resources"]["poses"],
    log:
        SCENE.log("poses"),
    benchmark:
        SCENE.benchmark("poses")
    script:
        "../workflow_scripts/stage.py"


rule masks:
    input:
        unpack(stage_inputs_of("masks")),
        capture=SCENE.capture_json,
    output:
        directory(SCENE.masks),
    params:
        settings=config["preprocess"]["masks"],
    threads: 1
    resources:
        **config["resources"]["masks"],
    log:
        SCENE.log("masks"),
    benchmark:
        SCENE.benchmark("masks")
    script:
        "../workflow_scripts/stage.py"


rule geometry:
    input:
        unpack(stage_inputs_of("geometry")),
        capture=SCENE.capture_json,
    output:
        mesh=SCENE.geometry["mesh"],
        summary=SCENE.geometry["summary"],
    params:
        settings=config["preprocess"]["geometry"],
    threads: PIPELINE.threads("preprocess")
    resources:
        **config["resources"]["geometry"],
    log:
        SCENE.log("geometry"),
    benchmark:
        SCENE.benchmark("geometry")
    script:
        "../workflow_scripts/stage.py"


rule uv:
    input:
        unpack(stage_inputs_of("uv")),
        capture=SCENE.capture_json,
    output:
        mesh_uv=SCENE.geometry["mesh_uv"],
        summary=SCENE.geometry["uv_summary"],
    params:
        settings=config["preprocess"]["uv"],
        texture_size=config["problem"].get("texture_size"),
        max_texture_size=config["problem"].get("max_texture_size"),
    threads: 1
    resources:
        **config["resources"]["uv"],
    log:
        SCENE.log("uv"),
    benchmark:
        SCENE.benchmark("uv")
    script:
        "../workflow_scripts/stage.py"
