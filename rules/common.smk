# Config validation and the small input functions every rule shares.
import json
from functools import lru_cache
from pathlib import Path

from snakemake.utils import validate


from dpi.adaptive import AdaptiveConfig, stop_rule_applies
from dpi.capture import inspect_capture, read_scene_options
from dpi.config_validation import check_config
from dpi.prior.sample import DEFAULT_MODELS
from dpi.settings import apply_preset
from dpi.solve.methods import METHODS as KNOWN_METHODS

apply_preset(config)  # the quality preset fills what the config leaves unset
check_config(config, workflow.source_path("config.schema.yaml"))  # one message with the key's path, before any job
validate(config, "config.schema.yaml")  # fills the schema's defaults

ADAPTIVE = config["adaptive"]
ADAPTIVE_CONFIG = AdaptiveConfig.from_dict(ADAPTIVE)
CAPTURES = config["captures_dir"]
RESULTS = config["results_dir"]
SCENES = config["scenes"]
METHODS = config["methods"]


wildcard_constraints:
    scene=r"[^/]+",
    method="|".join(KNOWN_METHODS),
    k=r"\d+",


def capture_dir(scene):
    """Input folder of a scene."""
    return Path(CAPTURES) / scene


def is_synthetic(scene):
    """Scenes listed under `synthetic:` are rendered by dpi when their folder is missing."""
    return scene in config["synthetic"]


@lru_cache(maxsize=None)
def given(scene):
    """What the capture provides (cameras, masks, mesh, mesh_has_uv), decided at parse time."""
    if is_synthetic(scene):
        have = not config["synthetic"][scene].get("photos_only", False)
        return {"cameras": have, "masks": have, "mesh": have, "mesh_has_uv": have}
    return inspect_capture(capture_dir(scene))


for _scene in SCENES:
    given(_scene)  # reads each capture's layout and scene.yaml now: a bad one stops before the DAG is built


def capture_files(wildcards):
    """Files the capture rule validates: the synthetic marker, or every file of the capture folder."""
    if is_synthetic(wildcards.scene):
        return [str(capture_dir(wildcards.scene) / ".synth.json")]
    root = capture_dir(wildcards.scene)
    return sorted(str(p) for p in root.rglob("*") if p.is_file() and not p.name.startswith("."))


def scene_inputs(wildcards):
    """capture.json plus the derived cameras/masks/mesh a scene needs (none when all are given)."""
    scene, have = wildcards.scene, given(wildcards.scene)
    inputs = {"capture": f"{RESULTS}/{scene}/capture.json"}
    if not have["cameras"]:
        inputs["cameras"] = f"{RESULTS}/{scene}/poses/transforms.json"
    if not have["masks"]:
        inputs["masks"] = f"{RESULTS}/{scene}/masks"
    if not have["mesh"]:
        inputs["mesh"] = f"{RESULTS}/{scene}/geometry/mesh_uv.ply"
    elif not have["mesh_has_uv"]:
        inputs["mesh"] = f"{RESULTS}/{scene}/geometry/mesh_uv.ply"
    return inputs


def method_samples(method):
    """Number of posterior samples of a method (its own `samples`, else the global one)."""
    return config["method_params"].get(method, {}).get("samples", config["samples"])


def drawn_samples(scene, method):
    """Samples of a method that exist in the end: all, or as many as the stop rule's plan says."""
    samples = method_samples(method)
    if first_samples(method) == samples:
        return samples
    plan = checkpoints.sample_plan.get(scene=scene, method=method).output[0]
    return json.loads(Path(plan).read_text())["samples"]


def method_params(method):
    """A method's settings without the sample count, so adding samples reruns no existing job."""
    return {k: v for k, v in config["method_params"].get(method, {}).items() if k != "samples"}


@lru_cache(maxsize=None)
def scene_family(scene):
    """Prior family of a scene: `prior` of its synthetic entry or scene.yaml, else the configured default."""
    if is_synthetic(scene):
        return config["synthetic"][scene].get("prior", config["illumination_prior"]["family"])
    return read_scene_options(capture_dir(scene)).get("prior", config["illumination_prior"]["family"])


def scene_prior(wildcards):
    """The diffusion prior of a scene's family: configured, else the shipped model (evaluation's naturalness)."""
    family = scene_family(wildcards.scene)
    return config["illumination_prior"]["checkpoints"].get(family, str(DEFAULT_MODELS[family]))


def prior_checkpoint(wildcards):
    """The diffusion prior a dps/sds job uses (none for other methods)."""
    return [scene_prior(wildcards)] if wildcards.method in ("dps", "sds") else []


def solve_params():
    """Renderer and problem settings shared by init, methods and evaluation."""
    return {"render": config["render"], "problem": config["problem"]}


def ground_truth_envmap(scene):
    """The capture's gt/envmap.exr, or None (synthetic captures always have one)."""
    path = capture_dir(scene) / "gt" / "envmap.exr"
    return str(path) if is_synthetic(scene) or path.is_file() else None


def all_figures():
    """The env-map grid of every scene."""
    return [f"{RESULTS}/{scene}/eval/envmaps.png" for scene in SCENES]


def adaptive_params(*prefixes):
    """The `adaptive` settings a rule uses (keys starting with a prefix), so changing others reruns nothing."""
    return {k: v for k, v in ADAPTIVE.items() if k.startswith(prefixes)}


def first_samples(method):
    """Samples of a method drawn whatever the stop rule decides (all when it does not apply)."""
    samples = method_samples(method)
    return ADAPTIVE_CONFIG.min_samples if stop_rule_applies(ADAPTIVE_CONFIG, samples) else samples


def sample_plans(scenes=SCENES):
    """The stop rule's plan files: inputs of whatever aggregates samples, so a missing or changed plan reruns it."""
    return [f"{RESULTS}/{scene}/{method}/plan.json" for scene in scenes for method in METHODS
            if first_samples(method) < method_samples(method)]


def fixed_evaluations():
    """Metric files that exist whatever the stop rule decides: each scene's init and first samples."""
    return [f"{RESULTS}/{scene}/eval/init/0.json" for scene in SCENES] + [
        f"{RESULTS}/{scene}/eval/{method}/{k}.json"
        for scene in SCENES
        for method in METHODS
        for k in range(first_samples(method))
    ]


def planned_evaluations(wildcards):
    """Metric files of the samples the stop rule's plans add (an input function: plans are checkpoints)."""
    return [
        f"{RESULTS}/{scene}/eval/{method}/{k}.json"
        for scene in SCENES
        for method in METHODS
        for k in range(first_samples(method), drawn_samples(scene, method))
    ]


def sample_envmaps(scene):
    """Per method of a scene, the env maps of the samples it draws: [(method, [paths])]."""
    return [(m, [f"{RESULTS}/{scene}/{m}/{k}/envmap.exr" for k in range(drawn_samples(scene, m))]) for m in METHODS]
