"""The shipped experiment configs are valid and plan the studies they describe (dry runs)."""

from workflow_helpers import REPO, planned_jobs, snakemake


def dry_run(tmp_path, name: str) -> dict[str, int]:
    """The experiment merged over dpi's defaults, planned in an empty directory."""
    return planned_jobs(snakemake(tmp_path, "-n", "--configfile", str(REPO / "experiments" / name)))


def test_prior_study_plans_every_method_on_two_objects_under_three_illuminations(tmp_path):
    jobs = dry_run(tmp_path, "priors.yaml")
    assert jobs["synth_capture"] == 6 and jobs["init"] == 6
    assert jobs["sample"] == 6 * 7 * 2 and jobs["evaluate"] == 6 * 7 * 2
    assert jobs["summary"] == 1 and jobs["report"] == 1


def test_roughness_study_plans_dps_samples_per_roughness(tmp_path):
    jobs = dry_run(tmp_path, "roughness.yaml")
    assert jobs["synth_capture"] == 5 and jobs["sample"] == 5 * 3 and jobs["report"] == 1
