"""The init's start study: do the init's readings (dpi.solve.init) keep the reading that makes the better init,
on every study scene?

For each scene of the posterior, calibration and resolution studies and the roughness study's 0.2 dielectric
(their captures, their workflow configs), the init's fit runs from each reading's start (dpi.solve.init.READINGS,
start_fit) to the end, recording its closing loss half-way (`half_way_loss`: which fit stops there) and at the
end, the views' log evidence at the end (`log_evidence`, dpi.solve.evidence: what the readings are compared by when
both finish), its mean data loss over steps 20-39 (`pilot_loss`: a 40-step pilot of each start, a rule tried
first), the roughness 25th percentile and median metallic, and the
held-out view PSNR of that start's init. A row per scene and start; `chosen` marks the reading the init keeps (the
one not stopped half-way; where both finish, the one most samples start from), `best` the one whose held-out views
are best.

    .venv/bin/python notebook/scripts/init_start_study.py [--studies posterior calibration resolution roughness]
        [--repeats 1]

Rows go to notebook/results/init_start_study.csv (scenes already there are not rerun; `chosen` is
recomputed from the rows with today's rule); then a table of the choices: per study and truth material, how often
the kept fit is the best one, and the held-out view PSNR of the kept fit, of the rough start alone (the init
before 2026-11-25) and of the best.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from dpi.studies.engine import (append_row, prepare_capture, read_rows, results_csv, settings_hash, work_dir,
                                workflow_config)
from dpi.studies.scenes import (POSTERIOR_SCENES, RESOLUTION_SCENES, calibration_scenes, repeat_scene, repeat_synth,
                                resolution_config, resolution_root, roughness_scenes)

CSV = Path(__file__).resolve().parents[1] / "results" / "init_start_study.csv"
COLUMNS = ("study", "scene", "roughness", "metallic", "start_roughness", "start_metallic", "pilot_loss",
           "half_way_loss", "closing_loss", "log_evidence", "init_roughness_p25", "init_metallic_median", "novel_psnr",
           "chosen", "best", "seconds")
PILOT = (20, 40)
"""steps whose mean data loss is `pilot_loss`: the second half of a 40-step pilot"""
TEXT = ("study", "scene")
STUDIES = ("posterior", "calibration", "resolution", "roughness")


def study_scenes(study: str, repeats: int) -> tuple[Path, dict[str, Any], dict[str, dict[str, Any]]]:
    """A study's folder, workflow config and scenes (folder name -> synth settings): the calibration and roughness
    studies' first `repeats` repeats of their scenes (the calibration study's: those in its CSV; the roughness
    study's: its dielectric at 0.2, the one a held-out view misread)."""
    if study == "posterior":
        return work_dir("posterior_study"), workflow_config(), {n: synth for n, (_, synth) in POSTERIOR_SCENES.items()}
    if study == "calibration":
        studied = {r["scene"] for r in read_rows(results_csv("calibration"), ("scene",))}
        return work_dir("calibration_study"), workflow_config(env_height=16), {
            repeat_scene(name, r): repeat_synth(synth, r)
            for name, synth in calibration_scenes().items() if name in studied for r in range(repeats)}
    if study == "roughness":
        from roughness_study import MAP_HEIGHT

        return work_dir("roughness_study"), workflow_config(env_height=MAP_HEIGHT), {
            repeat_scene(name, r): repeat_synth(synth, r)
            for name, synth in roughness_scenes([0.2]).items() for r in range(repeats)}
    return (resolution_root(work_dir("resolution_study"), 128, 64), resolution_config(128, 64),
            {name: synth for name, (_, synth) in RESOLUTION_SCENES.items()})


def scene_rows(study: str, root: Path, config: dict[str, Any], scene: str, synth: dict[str, Any]) -> list[dict]:
    """The init's fit from each start on one scene, scored on the held-out views; a row per start."""
    from dpi.config.pipeline import Pipeline
    from dpi.evaluation.sample_metrics import novel_view_metrics, render_held_out
    from dpi.io.layout import INIT
    from dpi.solve.decomposition import Decomposition
    from dpi.solve.init import READINGS, closing_loss, reading_evidence, roughness_p25, start_fit
    from dpi.solve.problem import SolveConfig
    from dpi.stages import load_problem
    from dpi.stages.seeding import seed_for

    problem = load_problem(prepare_capture(root, scene, synth, threads=2), SolveConfig.from_config(config, 2))
    cfg = Pipeline(config).init_settings
    rows = []
    for reading, start in READINGS.items():
        begin = time.perf_counter()
        run = start_fit(problem, cfg, reading, seed_for(scene, INIT))
        run.run(cfg.iterations // 2, progress=False)
        half_way = closing_loss(run.trace)
        run.run(cfg.iterations, progress=False)
        evidence = reading_evidence(problem, run, reading, seed_for(scene, INIT))
        log_env, materials = run.finish()
        pilot = [s["data"] for s in run.trace.steps[slice(*PILOT)] if s.get("data") is not None]
        renders = render_held_out(problem, Decomposition(log_env.exp(), materials), config["evaluate"]["spp"], 0)
        rows.append({"study": study, "scene": scene, "roughness": synth["roughness"], "metallic": synth["metallic"],
                     "start_roughness": start[0], "start_metallic": start[1], "pilot_loss": float(np.mean(pilot)),
                     "half_way_loss": half_way, "closing_loss": closing_loss(run.trace), "log_evidence": evidence,
                     "init_roughness_p25": roughness_p25(materials),
                     "init_metallic_median": float(materials.metallic.median()),
                     "novel_psnr": novel_view_metrics(problem, renders)["novel_psnr"],
                     "seconds": round(time.perf_counter() - begin, 1)})
    return mark(rows)


def row_settings(config: dict[str, Any], synth: dict[str, Any]) -> str:
    """The settings hash of a scene's rows: its capture and the init's settings."""
    return settings_hash({"synth": synth, "init": config["init"], "problem": config["problem"],
                          "render": config["render"]})


def mark(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Set `chosen` (the reading the init keeps, dpi.solve.init's rule: the one not stopped half-way, else the one
    most samples come from by the views' evidence) and `best` on one scene's two rows (rough start, glossy start)."""
    from dpi.solve.evidence import glossy_probability
    from dpi.solve.init import half_way_stop

    first, glossy = rows
    stopped = half_way_stop(glossy["half_way_loss"] / first["half_way_loss"])
    keep = stopped == "rough" or (stopped is None
                                  and glossy_probability(glossy["log_evidence"] - first["log_evidence"]) > 0.5)
    best = max(rows, key=lambda r: r["novel_psnr"])
    for row in rows:
        row.update(chosen=int(row is (glossy if keep else first)), best=int(row is best))
    return rows


def summary(rows: list[dict[str, Any]]) -> list[str]:
    """Per study and truth material: scenes, how often the chosen start is the best, and mean held-out view
    PSNR of the chosen start, of the first start alone (one start: no choice) and of the best start."""
    lines = [f"{'study':<12} {'truth':<16} {'scenes':>6} {'chosen = best':>13} {'chosen [dB]':>11} "
             f"{'first start [dB]':>16} {'best [dB]':>9}"]
    keys = sorted({(r["study"], f"r {r['roughness']:g} m {r['metallic']:g}") for r in rows})
    for study, truth in keys:
        sel = [r for r in rows if (r["study"], f"r {r['roughness']:g} m {r['metallic']:g}") == (study, truth)]
        scenes = sorted({r["scene"] for r in sel})
        pick = [next(r for r in sel if r["scene"] == s and r["chosen"]) for s in scenes]
        first = [next(r for r in sel if r["scene"] == s) for s in scenes]
        best = [next(r for r in sel if r["scene"] == s and r["best"]) for s in scenes]
        lines.append(f"{study:<12} {truth:<16} {len(scenes):>6} {int(sum(p['best'] for p in pick)):>6} of {len(scenes):<4}"
                     f"{np.mean([p['novel_psnr'] for p in pick]):>11.2f} {np.mean([f['novel_psnr'] for f in first]):>16.2f}"
                     f" {np.mean([b['novel_psnr'] for b in best]):>9.2f}")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--studies", nargs="*", default=list(STUDIES), choices=STUDIES)
    parser.add_argument("--repeats", type=int, default=1, help="calibration and roughness study repeats per scene")
    parser.add_argument("--out", type=Path, default=CSV)
    args = parser.parse_args()
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    done = {(r["study"], r["scene"]) for r in read_rows(args.out, TEXT)}
    for study in args.studies:
        root, config, scenes = study_scenes(study, args.repeats)
        for scene, synth in scenes.items():
            if (study, scene) in done:
                continue
            for row in scene_rows(study, root, config, scene, synth):
                append_row(args.out, row, COLUMNS, row_settings(config, synth))
            print(f"{study} {scene}: done", flush=True)
    rows = read_rows(args.out, TEXT)
    rows = [row for i in range(0, len(rows), 2) for row in mark(rows[i:i + 2])]
    args.out.unlink()
    for row in rows:
        append_row(args.out, row, COLUMNS, row["settings_hash"])
    print("\n".join(summary(rows)))


if __name__ == "__main__":
    main()
