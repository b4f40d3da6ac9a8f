"""A sample job killed mid-run (SIGKILL to Snakemake's process group) reruns cleanly with --rerun-incomplete,
continuing from the resume state the job had saved."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time

import numpy as np
import pytest
from workflow_helpers import REPO, SNAKEMAKE, TINY_CONFIG, planned_jobs, snakemake, write_config

pytestmark = pytest.mark.slow

# One sample whose optimisation runs long enough (a few seconds) to be killed in the middle,
# after its first resume state (saved before step CHECKPOINT_EVERY = 25).
RESUME_CONFIG = {**TINY_CONFIG, "methods": ["none"], "samples": 1,
                 "method_params": {"none": {"iterations": 100, "views_per_step": 1}}}
TARGET = "results/tiny/none/0/trace.json"
OUTPUTS = ["envmap.exr", "albedo.exr", "roughness.exr", "metallic.exr"]


def read_outputs(sample_dir):
    from dpi.io.exr import read_exr

    return {name: read_exr(sample_dir / name) for name in OUTPUTS}


def test_killed_sample_job_reruns_cleanly(tmp_path):
    write_config(tmp_path / "config.yaml", RESUME_CONFIG)
    snakemake(tmp_path, "results/tiny/init/log.json")
    sample_dir = tmp_path / "results" / "tiny" / "none" / "0"
    incomplete = tmp_path / ".snakemake" / "incomplete"

    cmd = [str(SNAKEMAKE), "-s", str(REPO / "Snakefile"), "--directory", str(tmp_path), "--cores", "1", TARGET]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
                            env={**os.environ, "PYTHONWARNINGS": "ignore"})
    try:
        deadline = time.monotonic() + 300
        # Kill as soon as the job's optimisation loop has saved its first resume state.
        while not (sample_dir / ".resume.pt").is_file():
            assert proc.poll() is None and time.monotonic() < deadline, "the sample job never saved its state"
            time.sleep(0.05)
        assert proc.poll() is None and not (sample_dir / "trace.json").exists(), "the job ended before the kill"
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()

    # Snakemake knows the job was cut off: its output is marked incomplete and the job is planned again.
    assert any(incomplete.iterdir())
    snakemake(tmp_path, "--unlock")
    assert planned_jobs(snakemake(tmp_path, "-n", "--rerun-incomplete", TARGET)) == {"sample": 1}

    snakemake(tmp_path, "--rerun-incomplete", TARGET)
    assert not any(incomplete.iterdir())
    # The rerun continued from the state the killed job saved, and removed it when done.
    trace = json.loads((sample_dir / "trace.json").read_text())
    assert trace["info"]["resumed_from_step"] in (25, 50, 75) and len(trace["steps"]) == 100
    assert not (sample_dir / ".resume.pt").exists()
    resumed = read_outputs(sample_dir)
    assert all(np.isfinite(image).all() for image in resumed.values())

    # Same result as an uninterrupted run (the sample's seed comes from scene, method and k).
    snakemake(tmp_path, "--forcerun", "sample", TARGET)
    fresh = read_outputs(sample_dir)
    for name in OUTPUTS:
        np.testing.assert_allclose(resumed[name], fresh[name], rtol=1e-4, atol=1e-5, err_msg=name)

