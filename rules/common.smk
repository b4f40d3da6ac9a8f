# The resolved config (dpi.config.pipeline) and the small input functions every rule shares.
import json
from pathlib import Path
from functools import lru_cache

from dpi.stages import (ENV_FILE, INIT, METHODS as KNOWN_METHODS, MIN_SAMPLES, PRIORS, REGISTRY, Pipeline,
                        check_no_links, check_unlocked, derived_inputs, lock_results, plain, resolve_config, stage_inputs, stop_rule_applies)

# dpi's defaults (dpi/data/config.yaml), ./config.yaml when present (the checkout's top-level file), then
# the --configfile files and --config values Snakemake merged into `config`; the preset fills what is
# unset, and the schema and settings dataclasses check it, with the key's path in one message, before
# the DAG is built. `dpi` resolves the same way (dpi.config.pipeline.resolve_config owns the order).
config.update(resolve_config(config))
PIPELINE = Pipeline(config)
LAYOUT = PIPELINE.layout
ADAPTIVE = PIPELINE.adaptive
SCENES = PIPELINE.scenes
METHODS = PIPELINE.methods

# Wildcard patterns of the per-scene layout: the same calls the stages and `dpi` make with real names.
SCENE = LAYOUT.scene("{scene}")
SAMPLE = SCENE.sample_files("{method}", "{k}")
INIT_FILES = SCENE.sample_files(INIT)


if workflow.is_main_process:  # a second run is told before Snakemake meets the first one's unfinished files
    check_unlocked(LAYOUT.results)
    check_no_links(LAYOUT.results)  # nothing written through a link out of results_dir


onstart:
    # one run per results folder, from whatever working directory (dpi.io.lock); not taken by a dry run
    lock_results(LAYOUT.results)


wildcard_constraints:
    scene=r"[^/]+",
    method="|".join(KNOWN_METHODS),
    k=r"\d+",


given = lru_cache(maxsize=None)(PIPELINE.given)
for _scene in SCENES:
    given(_scene)  # reads each capture's layout and scene.yaml now: a bad one stops before the DAG is built


def scene_layout(wildcards):
    return LAYOUT.scene(wildcards.scene)


def capture_files(wildcards):
    """Files the capture rule validates: the synthetic marker, or every file of the capture folder."""
    if PIPELINE.is_synthetic(wildcards.scene):
        return [str(LAYOUT.synth_marker(wildcards.scene))]
    root = LAYOUT.capture_dir(wildcards.scene)
    # a brace would read as a wildcard; dpi reads no such file (validation refuses braced image and mask names)
    return sorted(str(p) for p in root.rglob("*") if p.is_file() and not p.name.startswith(".")
                  and "{" not in str(p) and "}" not in str(p))


def scene_inputs(wildcards):
    """capture.json plus the derived cameras/masks/mesh a scene needs (none when the capture gives them all)."""
    scene = scene_layout(wildcards)
    return {"capture": scene.capture_json, **derived_inputs(given(wildcards.scene), scene)}


def drawn_samples(scene, method):
    """Samples of a method that exist in the end: all, or as many as the stop rule's plan says."""
    samples = PIPELINE.samples(method)
    if first_samples(method) == samples:
        return samples
    plan = checkpoints.sample_plan.get(scene=scene, method=method).output[0]
    return json.loads(Path(plan).read_text())["samples"]


def scene_prior(wildcards):
    """The diffusion prior of a scene's family (evaluation's naturalness)."""
    return PIPELINE.prior_checkpoint(wildcards.scene)


def method_prior(wildcards):
    """The diffusion prior a sample job reads (none for methods without it)."""
    prior = PIPELINE.method_prior(wildcards.scene, wildcards.method)
    return [] if prior is None else [prior]


def solve_params():
    """Renderer and problem settings shared by init, methods and evaluation."""
    return {"render": config["render"], "problem": config["problem"]}


def all_figures():
    """The env-map grid of every scene, and its uncertainty figure where a method draws 2 or more samples."""
    return [LAYOUT.scene(scene).envmap_figure for scene in SCENES] + (
        [LAYOUT.scene(scene).uncertainty_figure for scene in SCENES] if SPREAD_METHODS else [])


def adaptive_params(*prefixes):
    """The `adaptive` settings a rule uses (keys starting with a prefix), so changing others reruns nothing."""
    return {k: v for k, v in plain(ADAPTIVE).items() if k.startswith(prefixes)}


def first_samples(method):
    """Samples of a method drawn whatever the stop rule decides (all when it does not apply)."""
    samples = PIPELINE.samples(method)
    return MIN_SAMPLES if stop_rule_applies(ADAPTIVE, samples) else samples


def sample_plans(scenes=SCENES):
    """The stop rule's plan files: inputs of whatever aggregates samples, so a missing or changed plan reruns it."""
    return [LAYOUT.scene(scene).plan(method) for scene in scenes for method in METHODS
            if first_samples(method) < PIPELINE.samples(method)]


def fixed_evaluations():
    """Metric files that exist whatever the stop rule decides: each scene's init and first samples."""
    return [LAYOUT.scene(scene).evaluation(INIT) for scene in SCENES] + [
        LAYOUT.scene(scene).evaluation(method, k)
        for scene in SCENES
        for method in METHODS
        for k in range(first_samples(method))
    ]


def planned_evaluations(wildcards):
    """Metric files of the samples the stop rule's plans add (an input function: plans are checkpoints)."""
    return [
        LAYOUT.scene(scene).evaluation(method, k)
        for scene in SCENES
        for method in METHODS
        for k in range(first_samples(method), drawn_samples(scene, method))
    ]


SPREAD_METHODS = [m for m in METHODS if first_samples(m) >= 2]
"""methods whose samples have a spread to map: 2 or more, whatever the stop rule decides"""


def sample_folders(scene):
    """Per method with a spread, the folders of the samples it draws: [(method, [folders])]."""
    return [(m, folders) for m, folders in sample_rows(scene) if m in SPREAD_METHODS]


def sample_rows(scene):
    """Per method of a scene, the folders of the samples it draws: [(method, [folders])] (the export's variants)."""
    return [(m, [LAYOUT.scene(scene).sample_dir(m, k) for k in range(drawn_samples(scene, m))]) for m in METHODS]


def all_exports():
    """Each scene's glTF and USD assets."""
    return [LAYOUT.scene(scene).export_asset(suffix) for scene in SCENES for suffix in ("glb", "usda")]


def sample_envmaps(scene):
    """Per method of a scene, the env maps of the samples it draws: [(method, [paths])]."""
    return [(m, [folder / ENV_FILE for folder in folders]) for m, folders in sample_rows(scene)]
