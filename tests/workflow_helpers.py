"""What the workflow tests share: the tiny synthetic config and a way to run Snakemake on it."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parent.parent
SNAKEMAKE = Path(sys.executable).parent / "snakemake"

TINY_CONFIG = {
    "scenes": ["tiny"],
    "synthetic": {"tiny": {"views": 4, "held_out_every": 4, "width": 16, "height": 16, "spp": 16,
                           "env_height": 8, "texture_size": 8, "seed": 1}},
    "methods": ["none", "smoothness"],
    "samples": 2,
    "render": {"spp": 4},
    "problem": {"env_height": 4, "texture_size": 8},
    "init": {"iterations": 3, "views_per_step": 2},
    "method_params": {"none": {"iterations": 2, "views_per_step": 1},
                      "smoothness": {"iterations": 2, "views_per_step": 1}},
    "evaluate": {"spp": 4},
    "threads": {"synth": 1, "init": 1, "sample": 1, "evaluate": 1},
}


def snakemake(workdir: Path, *args: str) -> str:
    """Run snakemake on the repository's workflow in `workdir`; returns its output (fails on error)."""
    cmd = [str(SNAKEMAKE), "-s", str(REPO / "Snakefile"), "--directory", str(workdir), "--cores", "2", *args]
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=900)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc.stdout + proc.stderr


def planned_jobs(output: str) -> dict[str, int]:
    """Job counts per rule from a dry run's 'Job stats' table ({} when nothing is to be done)."""
    counts = {}
    for rule, count in re.findall(r"^(\w+)\s+(\d+)\s*$", output, flags=re.M):
        if rule != "total":
            counts[rule] = int(count)
    return counts


def write_config(path: Path, config: dict) -> Path:
    path.write_text(yaml.safe_dump(config))
    return path
