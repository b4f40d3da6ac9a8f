"""End-to-end Snakemake behaviour on a tiny synthetic scene: run, no-op rerun, targeted reruns, skips."""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from workflow_helpers import REPO, SNAKEMAKE, TINY_CONFIG, planned_jobs, snakemake, write_config

from dpi.io.exr import read_exr

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> Path:
    """A working directory where the tiny workflow has run once, end to end."""
    wd = tmp_path_factory.mktemp("workflow")
    write_config(wd / "config.yaml", TINY_CONFIG)
    snakemake(wd)
    return wd


def test_default_target_runs_end_to_end(workdir):
    rows = list(csv.DictReader(open(workdir / "results" / "eval" / "summary.csv")))
    assert {(r["scene"], r["method"]) for r in rows} == {("tiny", "init"), ("tiny", "none"), ("tiny", "smoothness")}
    for row in rows:
        assert float(row["novel_psnr"]) > 5 and float(row["env_psnr"]) > 0
        assert row["samples"] == ("1" if row["method"] == "init" else "2")
    assert (workdir / "results" / "tiny" / "eval" / "envmaps.png").is_file()
    assert "<table" in (workdir / "results" / "report.html").read_text()
    assert (workdir / "results" / "report" / "tiny" / "held_out.png").is_file()
    for k in range(2):
        assert (workdir / "results" / "tiny" / "none" / str(k) / "envmap.exr").is_file()
    spread = read_exr(workdir / "results" / "tiny" / "none" / "env_log_std.exr")
    assert spread.shape[:2] == read_exr(workdir / "results" / "tiny" / "none" / "0" / "envmap.exr").shape[:2]
    assert np.isfinite(spread).all() and spread.max() > 0  # two free fits from two seeds differ somewhere
    mean = read_exr(workdir / "results" / "tiny" / "none" / "env_mean.exr")
    assert mean.shape == read_exr(workdir / "results" / "tiny" / "none" / "0" / "envmap.exr").shape
    assert np.isfinite(mean).all() and mean.min() > 0
    assert (workdir / "results" / "report" / "tiny" / "uncertainty.png").is_file()
    assert (workdir / "results" / "tiny" / "logs" / "init.log").is_file()
    export = workdir / "results" / "tiny" / "export"
    assert (export / "tiny.glb").is_file() and (export / "tiny.usda").is_file()
    assert {p.name for p in (export / "envmaps").glob("*.hdr")} == {"init.hdr", "none_0.hdr", "none_1.hdr",
                                                                    "smoothness_0.hdr", "smoothness_1.hdr"}


def test_second_run_does_nothing(workdir):
    assert planned_jobs(snakemake(workdir, "-n")) == {}


def test_changing_one_method_reruns_only_its_jobs(workdir, tmp_path):
    changed = {"method_params": {"smoothness": {"iterations": 3, "views_per_step": 1}}}
    out = snakemake(workdir, "-n", "--configfile", str(write_config(tmp_path / "c.yaml", changed)))
    assert planned_jobs(out) == {"sample": 2, "evaluate": 2, "envmap_figure": 1, "uncertainty": 1, "export": 1,
                                 "summary": 1, "report": 1, "all": 1}
    assert "output: results/tiny/none/0/" not in out and "output: results/tiny/none/1/" not in out


def test_adding_a_sample_runs_only_the_new_one(workdir, tmp_path):
    more = write_config(tmp_path / "more.yaml", {"samples": 3, "adaptive": {"sample_stop": False}})
    out = snakemake(workdir, "-n", "--configfile", str(more))
    assert planned_jobs(out) == {"sample": 2, "evaluate": 2, "envmap_figure": 1, "uncertainty": 1, "export": 1,
                                 "summary": 1, "report": 1, "all": 1}
    assert "output: results/tiny/none/2/" in out and "output: results/tiny/none/0/" not in out


def test_given_inputs_skip_their_stages_and_missing_ones_are_planned(workdir, tmp_path):
    import trimesh

    captures = tmp_path / "captures"
    shutil.copytree(workdir / "captures" / "tiny", captures / "given")
    (captures / "given" / ".synth.json").unlink()
    for kind in ("nocams", "nomasks", "nouv", "photos"):
        shutil.copytree(captures / "given", captures / kind)
    (captures / "nocams" / "transforms.json").unlink()
    shutil.rmtree(captures / "nomasks" / "masks")
    mesh = trimesh.load(captures / "nouv" / "mesh.ply", process=False)
    trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).export(captures / "nouv" / "mesh.ply")
    for name in ("transforms.json", "mesh.ply"):
        (captures / "photos" / name).unlink()
    shutil.rmtree(captures / "photos" / "masks")
    config = {**TINY_CONFIG, "scenes": ["given", "nocams", "nomasks", "nouv", "photos"], "synthetic": {}}
    write_config(tmp_path / "config.yaml", config)
    expected = {
        "given": {},
        "nocams": {"poses": 1},
        "nomasks": {"poses": 1, "masks": 1},
        "nouv": {"uv": 1},
        "photos": {"poses": 1, "masks": 1, "geometry": 1, "uv": 1},
    }
    for scene, stages in expected.items():
        out = snakemake(tmp_path, "-n", f"results/{scene}/init/log.json")
        assert planned_jobs(out) == {"capture": 1, **stages, "init": 1}, scene


def summary_samples(wd: Path) -> dict[str, str]:
    return {r["method"]: r["samples"] for r in csv.DictReader(open(wd / "results" / "eval" / "summary.csv"))}


def test_stop_rule_draws_the_remaining_samples_only_when_the_first_ones_differ(workdir, tmp_path):
    wd = tmp_path / "wd"
    shutil.copytree(workdir, wd)
    agree = {"samples": 3, "adaptive": {"agree_tolerance": 1e9}}
    out = snakemake(wd, "--configfile", str(write_config(tmp_path / "agree.yaml", agree)))
    plan = json.loads((wd / "results" / "tiny" / "none" / "plan.json").read_text())
    assert plan["samples"] == 2 and plan["requested"] == 3 and "agree" in plan["reason"]
    assert not (wd / "results" / "tiny" / "none" / "2").exists()
    assert summary_samples(wd) == {"init": "1", "none": "2", "smoothness": "2"}
    assert "agree_tolerance" in (wd / "results" / "tiny" / "logs" / "none" / "plan.log").read_text()

    differ = {"samples": 3, "adaptive": {"agree_tolerance": 0.0}}
    out = snakemake(wd, "--configfile", str(write_config(tmp_path / "differ.yaml", differ)))
    assert "checkpoint sample_plan" in out
    assert json.loads((wd / "results" / "tiny" / "none" / "plan.json").read_text())["samples"] == 3
    assert (wd / "results" / "tiny" / "none" / "2" / "envmap.exr").is_file()
    assert summary_samples(wd) == {"init": "1", "none": "3", "smoothness": "3"}


def test_dpi_commands_give_the_workflow_files(workdir, tmp_path, monkeypatch):
    """`dpi capture/init/sample/evaluate --config my.yaml` in a run directory writes what `snakemake --configfile
    my.yaml` writes there: the same settings (defaults, ./config.yaml, my.yaml, preset), paths and seeds."""
    import numpy as np

    from dpi.cli import main
    from dpi.io.exr import read_exr
    from dpi.io.layout import INIT, SceneLayout

    wd = tmp_path / "wd"
    wd.mkdir()
    shutil.copy(workdir / "config.yaml", wd / "config.yaml")
    shutil.copytree(workdir / "captures", wd / "captures")
    # my.yaml changes keys that config.yaml sets and keys it leaves to the defaults and the preset
    my = write_config(wd / "my.yaml", {"init": {"lr_env": 0.05}, "method_params": {"none": {"iterations": 3}},
                                       "evaluate": {"spp": 8}})
    workflow, ours = SceneLayout(wd / "results" / "tiny"), SceneLayout(wd / "results_cli" / "tiny")
    snakemake(wd, str(workflow.evaluation(INIT).relative_to(wd)), str(workflow.evaluation("none", 0).relative_to(wd)),
              "--configfile", str(my))
    write_config(wd / "cli.yaml", {"results_dir": "results_cli"})
    monkeypatch.chdir(wd)
    for command in (["capture", "tiny"], ["init", "tiny"], ["sample", "tiny", "none", "0"], ["evaluate", "tiny", INIT],
                    ["evaluate", "tiny", "none", "0"]):
        assert main([*command, "--config", "my.yaml", "--config", "cli.yaml"]) == 0, command

    assert json.loads(ours.capture_json.read_text()) == json.loads(workflow.capture_json.read_text())
    for method in (INIT, "none"):
        for name, path in workflow.sample_files(method, 0).items():
            if name != "trace":
                np.testing.assert_allclose(read_exr(ours.sample_files(method, 0)[name]), read_exr(path), rtol=1e-5,
                                           atol=1e-6, err_msg=f"{method} {name}")
        theirs, mine = (json.loads(layout.evaluation(method, 0).read_text())["metrics"] for layout in (workflow, ours))
        for key, value in theirs.items():
            if key not in ("sample_seconds", "notes"):
                numeric = isinstance(value, (float, list, dict))
                assert mine[key] == (pytest.approx(value, rel=1e-4) if numeric else value), key
        views = sorted(workflow.evaluation_views(method, 0).glob("*.exr"))  # (Snakemake adds a timestamp file)
        assert views
        for view in views:
            np.testing.assert_allclose(read_exr(ours.evaluation_views(method, 0) / view.name), read_exr(view),
                                       rtol=1e-5, atol=1e-6)


def test_a_second_run_while_the_first_writes_is_told_so_in_dpis_words(workdir):
    """From the same working folder: the results lock is asked for when the workflow is read, before Snakemake
    would call the first run's unfinished files incomplete and advise --rerun-incomplete."""
    hold = ("import sys, time; from dpi.io.lock import lock_results; lock_results(sys.argv[1]); "
            "print('held', flush=True); time.sleep(60)")
    holder = subprocess.Popen([sys.executable, "-c", hold, str(workdir / "results")], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        proc = subprocess.run([str(SNAKEMAKE), "-s", str(REPO / "Snakefile"), "--directory", str(workdir), "--cores",
                               "1", "--forcerun", "report"], capture_output=True, text=True, timeout=300)
    finally:
        holder.kill()
        holder.wait()
    out = proc.stdout + proc.stderr
    assert proc.returncode != 0
    assert f"another dpi run (process {holder.pid}) is writing here" in out and "rerun-incomplete" not in out


def test_a_link_inside_results_is_refused_before_anything_runs(workdir, tmp_path):
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    folder = workdir / "results" / "tiny" / "none"
    kept = folder.with_name("none_kept")
    folder.rename(kept)
    try:
        folder.symlink_to(outside, target_is_directory=True)
        proc = subprocess.run([str(SNAKEMAKE), "-s", str(REPO / "Snakefile"), "--directory", str(workdir), "--cores",
                               "1"], capture_output=True, text=True, timeout=300)
    finally:
        folder.unlink()
        kept.rename(folder)
    assert proc.returncode != 0 and "results/tiny/none: is a link" in proc.stdout + proc.stderr
    assert list(outside.iterdir()) == []
