# Capture preparation: synthetic captures, validation, and the stages that derive missing inputs.


rule synth_capture:
    output:
        f"{CAPTURES}/{{scene}}/.synth.json",
    params:
        synth=lambda w: config["synthetic"][w.scene],
    threads: config["threads"]["synth"]
    log:
        f"{RESULTS}/{{scene}}/logs/synth.log",
    script:
        "../workflow_scripts/synth.py"


rule capture:
    input:
        capture_files,
    output:
        f"{RESULTS}/{{scene}}/capture.json",
    params:
        capture=lambda w: str(capture_dir(w.scene)),
    log:
        f"{RESULTS}/{{scene}}/logs/capture.log",
    script:
        "../workflow_scripts/capture.py"


# Placeholders for captures without cameras, masks or a UV-mapped mesh (real-world photos):
# they are only scheduled when a capture lacks the input, and stop with a clear message.
rule poses:
    input:
        f"{RESULTS}/{{scene}}/capture.json",
    output:
        f"{RESULTS}/{{scene}}/poses/transforms.json",
    params:
        stage="poses (COLMAP)",
    log:
        f"{RESULTS}/{{scene}}/logs/poses.log",
    script:
        "../workflow_scripts/not_available.py"


rule masks:
    input:
        f"{RESULTS}/{{scene}}/capture.json",
    output:
        f"{RESULTS}/{{scene}}/masks/done.flag",
    params:
        stage="foreground masks",
    log:
        f"{RESULTS}/{{scene}}/logs/masks.log",
    script:
        "../workflow_scripts/not_available.py"


rule uv:
    input:
        f"{RESULTS}/{{scene}}/capture.json",
    output:
        f"{RESULTS}/{{scene}}/geometry/mesh_uv.ply",
    params:
        stage="surface reconstruction / UV atlas",
    log:
        f"{RESULTS}/{{scene}}/logs/uv.log",
    script:
        "../workflow_scripts/not_available.py"
