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


# Stages that derive what a photo capture lacks (dpi.preprocess). Each is scheduled only when the
# capture does not give its output (see `given` and `scene_inputs` in common.smk):
# poses (COLMAP) -> masks (GrabCut / keying) -> geometry (carved SDF + cleanup) -> uv (xatlas).


def derived_cameras(wildcards):
    """The poses stage's outputs a later stage reads, when the capture has no cameras."""
    if given(wildcards.scene)["cameras"]:
        return {}
    return {"cameras": f"{RESULTS}/{wildcards.scene}/poses/transforms.json",
            "points": f"{RESULTS}/{wildcards.scene}/poses/points.ply"}


def derived_masks(wildcards):
    """The masks folder the geometry stage reads, when the capture has no masks."""
    return {} if given(wildcards.scene)["masks"] else {"masks": f"{RESULTS}/{wildcards.scene}/masks"}


def uv_source(wildcards):
    """The mesh the uv stage parametrises: the reconstructed one, or the capture's own (in capture.json)."""
    return {} if given(wildcards.scene)["mesh"] else {"mesh": f"{RESULTS}/{wildcards.scene}/geometry/mesh.ply"}


rule poses:
    input:
        capture=f"{RESULTS}/{{scene}}/capture.json",
    output:
        cameras=f"{RESULTS}/{{scene}}/poses/transforms.json",
        points=f"{RESULTS}/{{scene}}/poses/points.ply",
        summary=f"{RESULTS}/{{scene}}/poses/summary.json",
    params:
        settings=config["preprocess"]["sfm"],
    threads: config["threads"]["preprocess"]
    resources:
        mem_mb=config["resources"]["poses"]["mem_mb"],
        runtime=config["resources"]["poses"]["runtime"],
    log:
        f"{RESULTS}/{{scene}}/logs/poses.log",
    benchmark:
        f"{RESULTS}/{{scene}}/benchmarks/poses.tsv"
    script:
        "../workflow_scripts/poses.py"


rule masks:
    input:
        unpack(derived_cameras),
        capture=f"{RESULTS}/{{scene}}/capture.json",
    output:
        directory(f"{RESULTS}/{{scene}}/masks"),
    params:
        settings=config["preprocess"]["masks"],
    threads: 1
    resources:
        mem_mb=config["resources"]["masks"]["mem_mb"],
        runtime=config["resources"]["masks"]["runtime"],
    log:
        f"{RESULTS}/{{scene}}/logs/masks.log",
    benchmark:
        f"{RESULTS}/{{scene}}/benchmarks/masks.tsv"
    script:
        "../workflow_scripts/masks.py"


rule geometry:
    input:
        unpack(derived_cameras),
        unpack(derived_masks),
        capture=f"{RESULTS}/{{scene}}/capture.json",
    output:
        mesh=f"{RESULTS}/{{scene}}/geometry/mesh.ply",
        summary=f"{RESULTS}/{{scene}}/geometry/summary.json",
    params:
        settings=config["preprocess"]["geometry"],
    threads: 1
    resources:
        mem_mb=config["resources"]["geometry"]["mem_mb"],
        runtime=config["resources"]["geometry"]["runtime"],
    log:
        f"{RESULTS}/{{scene}}/logs/geometry.log",
    benchmark:
        f"{RESULTS}/{{scene}}/benchmarks/geometry.tsv"
    script:
        "../workflow_scripts/geometry.py"


rule uv:
    input:
        unpack(uv_source),
        capture=f"{RESULTS}/{{scene}}/capture.json",
    output:
        f"{RESULTS}/{{scene}}/geometry/mesh_uv.ply",
    params:
        settings=config["preprocess"]["uv"],
    threads: 1
    resources:
        mem_mb=config["resources"]["uv"]["mem_mb"],
        runtime=config["resources"]["uv"]["runtime"],
    log:
        f"{RESULTS}/{{scene}}/logs/uv.log",
    benchmark:
        f"{RESULTS}/{{scene}}/benchmarks/uv.tsv"
    script:
        "../workflow_scripts/uv.py"
