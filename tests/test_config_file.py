"""The top-level config.yaml a user edits: valid, and read alike by the Snakefile and the `dpi` command."""

from __future__ import annotations

import os
import subprocess

import yaml
from workflow_helpers import REPO, SNAKEMAKE, planned_jobs

from dpi.cli import main
from dpi.config.pipeline import merge, read_yaml, resolve_config

TOP_LEVEL = REPO / "config.yaml"


def workflow_config(workdir) -> tuple[dict, str]:
    """The settings the Snakefile resolves in `workdir` (as `dpi config` prints them) and its dry run's output."""
    dump = workdir / "dump.smk"
    dump.write_text(f'include: "{REPO / "Snakefile"}"\n\n'
                    'Path("resolved.yaml").write_text(__import__("yaml").safe_dump(PIPELINE.describe()))\n')
    cmd = [str(SNAKEMAKE), "-s", str(dump), "--directory", str(workdir), "--cores", "2", "-n", "all"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "PYTHONWARNINGS": "ignore"})
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return yaml.safe_load((workdir / "resolved.yaml").read_text()), proc.stdout + proc.stderr


def test_the_top_level_configs_examples_are_valid_settings(monkeypatch):
    """config.yaml sets nothing; each commented example, uncommented, is a setting the config check accepts."""
    import re

    lines = TOP_LEVEL.read_text().splitlines()
    example = re.compile(r"^# [a-z_]+:( \[| \{| [\w/.-]+$|$)|^#   [a-z_]+: \{")
    examples = [line[2:] for line in lines if example.match(line)]
    edited = yaml.safe_load("\n".join(examples))
    assert {"scenes", "methods", "preset", "problem", "evaluate", "threads", "method_params"} <= set(edited)
    monkeypatch.chdir(REPO)
    config = resolve_config(edited)
    assert config["preset"] == "draft" and config["method_params"]["dps"]["samples"] == 5


def test_dpi_config_and_snakemake_resolve_the_top_level_file_alike(tmp_path, monkeypatch, capsys):
    edited = merge(read_yaml(TOP_LEVEL), {"samples": 1, "evaluate": {"spp": 8}, "problem": {"resolution": 32},
                                          "method_params": {"dps": {"samples": 1}}})
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(edited))
    monkeypatch.chdir(tmp_path)
    assert main(["config"]) == 0
    printed = yaml.safe_load(capsys.readouterr().out)
    assert printed["evaluate"]["spp"] == 8 and printed["problem"]["resolution"] == 32  # the file over the defaults
    assert printed["method_params"]["dps"]["samples"] == 1

    resolved, dry_run = workflow_config(tmp_path)
    assert resolved == printed
    jobs = planned_jobs(dry_run)
    assert jobs["sample"] == len(printed["scenes"]) * len(printed["methods"])  # one sample of each method

