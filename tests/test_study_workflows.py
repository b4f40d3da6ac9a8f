"""A study written as a workflow config (`--workflow`) is valid and plans the study's own scenes, methods and
samples (dry runs): one definition of each study, two ways to run it."""

import subprocess
import sys

from workflow_helpers import REPO, planned_jobs, snakemake

from dpi.studies.scenes import POSTERIOR_SCENES


def dry_run(tmp_path, study: str, *args: str) -> dict[str, int]:
    """The study's workflow config, written by its script and planned in an empty directory."""
    config = tmp_path / f"{study}.yaml"
    subprocess.run([sys.executable, str(REPO / "benchmarks" / study / f"{study}.py"), *args, "--workflow", str(config)],
                   check=True, capture_output=True, cwd=tmp_path)
    return planned_jobs(snakemake(tmp_path, "-n", "--configfile", str(config)))


def test_posterior_study_plans_every_method_on_every_scene(tmp_path):
    jobs = dry_run(tmp_path, "posterior", "--seeds", "0", "1")
    scenes, methods = len(POSTERIOR_SCENES), len(("none", "smoothness", "sds", "dip", "gan", "reni", "dps"))
    assert jobs["synth_capture"] == scenes and jobs["init"] == scenes
    assert jobs["sample"] == scenes * methods * 2 and jobs["evaluate"] == scenes * methods * 2
    assert jobs["summary"] == 1 and jobs["report"] == 1


def test_roughness_study_plans_dps_samples_per_roughness_and_repeat(tmp_path):
    jobs = dry_run(tmp_path, "roughness", "--roughness", "0.05", "0.5", "--repeats", "2", "--samples", "3")
    assert jobs["synth_capture"] == 2 * 2 and jobs["sample"] == 2 * 2 * 3 and jobs["report"] == 1
