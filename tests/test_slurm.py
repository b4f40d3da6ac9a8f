"""The tiny workflow through `snakemake --profile profiles/slurm` on a real single-node Slurm on 127.0.0.1.

The fixture starts the cluster with scripts/slurm_local.sh (which apt-installs munge and Slurm
when they are missing, as root) and stops its daemons afterwards.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import time

import pytest
import yaml
from workflow_helpers import REPO, SNAKEMAKE, TINY_CONFIG, snakemake, write_config

pytestmark = [pytest.mark.slurm, pytest.mark.slow]

PARTITION = "debug"
SLURM_LOCAL = REPO / "scripts" / "slurm_local.sh"
# One method, two samples. The capture is prepared locally; through Slurm go 10 jobs in 5 waves:
# init; 2 x sample, evaluate_init; 2 x evaluate, envmap_figure, uncertainty; summary; report.
SLURM_CONFIG = {
    **TINY_CONFIG,
    "methods": ["none"],
    "resources": {"init": {"mem_mb": 500}, "sample": {"mem_mb": 500}, "evaluate": {"mem_mb": 500}},
}


@pytest.fixture(scope="module")
def slurm(tmp_path_factory) -> dict[str, str]:
    """Environment of a running local Slurm cluster (SLURM_CONF set); its daemons stop afterwards."""
    if os.geteuid() != 0:
        pytest.skip("starting a local Slurm cluster needs root (munged/slurmctld/slurmd run as root)")
    if shutil.which("slurmctld") is None and shutil.which("apt-get") is None:
        pytest.skip("Slurm is not installed and apt-get is not available to install it")
    state = tmp_path_factory.mktemp("slurm")
    env = {**os.environ, "SLURM_LOCAL_DIR": str(state), "SLURM_LOCAL_PARTITION": PARTITION}
    stop = lambda: subprocess.run(["bash", str(SLURM_LOCAL), "stop"], env=env, capture_output=True)  # noqa: E731
    start = subprocess.run(["bash", str(SLURM_LOCAL), "start"], env=env, capture_output=True, text=True, timeout=900)
    if start.returncode != 0:
        stop()
        pytest.fail(f"scripts/slurm_local.sh start failed:\n{start.stdout}\n{start.stderr}")
    yield {**env, "SLURM_CONF": str(state / "slurm.conf")}
    stop()


def profile_default_resources(**overrides) -> list[str]:
    """The profile's default-resources with some entries replaced (e.g. the placeholder partition)."""
    profile = yaml.safe_load((REPO / "profiles" / "slurm" / "config.yaml").read_text())
    resources = dict(entry.split("=", 1) for entry in profile["default-resources"])
    resources.update({key: str(value) for key, value in overrides.items()})
    return [f"{key}={value}" for key, value in resources.items()]


def test_tiny_workflow_runs_through_slurm(slurm, tmp_path):
    write_config(tmp_path / "config.yaml", SLURM_CONFIG)
    snakemake(tmp_path, "results/tiny/capture.json")  # locally: each Slurm job costs ~30 s on 2 busy cores
    cmd = ["timeout", "-s", "INT", "600", str(SNAKEMAKE), "-s", str(REPO / "Snakefile"),
           "--directory", str(tmp_path), "--profile", str(REPO / "profiles" / "slurm"),
           "--default-resources", *profile_default_resources(slurm_partition=f'"{PARTITION}"', mem_mb=500),
           "--slurm-keep-successful-logs", "--slurm-init-seconds-before-status-checks", "5"]
    started = time.monotonic()
    proc = subprocess.run(cmd, capture_output=True, text=True, env={**slurm, "PYTHONWARNINGS": "ignore"},
                          cwd=tmp_path)
    output = proc.stdout + proc.stderr
    print(f"Slurm workflow wall time: {time.monotonic() - started:.1f} s")
    assert proc.returncode == 0, output[-5000:]

    results = tmp_path / "results"
    assert (results / "eval" / "summary.csv").is_file()
    assert (results / "tiny" / "eval" / "envmaps.png").is_file()
    for k in range(2):
        assert (results / "tiny" / "none" / str(k) / "envmap.exr").is_file()

    # Every job was an sbatch submission, and Slurm ran each of them to completion.
    job_ids = re.findall(r"submitted with SLURM jobid (\d+)", output)
    assert len(job_ids) == 10, output[-5000:]
    listing = subprocess.run(["squeue", "--states=all", "-h", "-o", "%i %T %P"], capture_output=True, text=True,
                             env=slurm, check=True).stdout
    states = {line.split()[0]: line.split()[1:] for line in listing.splitlines()}
    assert all(states.get(job_id) == ["COMPLETED", PARTITION] for job_id in job_ids), listing
    # The plugin keeps one Slurm log per job under .snakemake/slurm_logs/rule_<name>/.
    logged_rules = {p.name for p in (tmp_path / ".snakemake" / "slurm_logs").iterdir()}
    assert {"rule_init", "rule_sample", "rule_evaluate", "rule_summary", "rule_report"} <= logged_rules
