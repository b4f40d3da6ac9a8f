"""Readings study: a mirror and a rough object that explain the same views (issue 65).

Scenes: a bumpy torus of roughness 0.05 (metal), 0.2, 0.5 and 0.8 (dielectrics) under a clear sky with a low sun,
a procedural room and a held-out real panorama that no study scene uses (with --panoramas), seen in 8 views of
32 px on a 150 deg arc or in 16 views of 48 px all around; with --held-out, scenes no rule of the init was designed
on instead: another torus under a 12 and a 45 deg sun and a beach panorama, on the arc. Per scene and repeat (its own capture noise and init)
the workflow's init fits both readings (dpi.solve.init) and `dps` draws `--samples` samples through the stage
functions; one row of benchmarks/readings/readings.csv per scene and repeat: the init's closing-loss ratio
(glossy over rough; half-way, and `stopped` 1, where one of the two fits stopped there), the evidence's log Bayes
factor glossy over rough where both finished (empty where one stopped), the kept reading, the share of
samples that started from the glossy reading, the init's and the samples' held-out views and env PSNR (mean and
worst sample), the samples' mean map, spread and calibration, and the init's seconds. Then a table per scene and
the metal / rough spread ratios (Fig. 9).

    .venv/bin/python benchmarks/readings/readings.py --panoramas ../shared/panoramas [--scenes ...] [--repeats 3]
        [--samples 4] [--jobs 2] [--held-out] [--cost | --forced]

With --cost, the init is timed with both readings and with the rough one alone, one after the other on the first
repeat's captures (benchmarks/readings/readings_cost.csv). With --forced, each reading's init is fitted alone and
`dps` draws samples from each (one row per sample, benchmarks/readings/readings_forced.csv): the data the readings'
rule was chosen on. Rows already in a CSV with the same settings hash are kept.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from dpi.studies.engine import (Job, append_row, job_settings, pool, prepare_capture, prepare_job, read_rows,
                                results_csv, run_job, settings_hash, work_dir, workflow_config)
from dpi.studies.scenes import repeat_scene, repeat_synth

WORK = work_dir("readings_study")
CSV = results_csv("readings")
COLUMNS = ("scene", "light", "views", "roughness", "metallic", "repeat", "reading", "method", "seed",
           "closing_loss", "novel_psnr", "env_psnr", "env_ssim", "albedo_mse", "train_fit", "train_fit_over_truth",
           "seconds")
TEXT = ("scene", "light", "views", "reading", "method")
GROUP_COLUMNS = ("scene", "light", "views", "roughness", "metallic", "repeat", "samples", "ratio", "stopped",
                 "log_bayes_factor", "kept",
                 "glossy_samples", "init_novel_psnr", "init_env_psnr", "init_seconds", "novel_psnr", "env_psnr",
                 "albedo_mse", "seconds", "min_novel_psnr", "min_env_psnr", "env_mean_psnr", "env_sigma2_sample",
                 "calibration")
GROUP_TEXT = ("scene", "light", "views", "kept")
ROUGHNESSES = (0.05, 0.2, 0.5, 0.8)
LIGHTS = {"sun": {"environment": "sunsky", "sun_elevation_deg": 10.0, "sun_azimuth_deg": 200.0, "prior": "outdoor"},
          "room": {"environment": "indoor", "environment_seed": 41, "prior": "indoor"},
          "real": {"panorama": "hilly_terrain_01_1k.hdr", "prior": "outdoor"}}
"""a clear sky with a low sun, a procedural room, a held-out real panorama with a sun that no study scene uses"""
HELD_OUT_LIGHTS = {"sun12": {"environment": "sunsky", "sun_elevation_deg": 12.0, "sun_azimuth_deg": 120.0,
                              "prior": "outdoor"},
                   "sun45": {"environment": "sunsky", "sun_elevation_deg": 45.0, "sun_azimuth_deg": 120.0,
                              "prior": "outdoor"},
                   "beach": {"panorama": "spiaggia_di_mondello_1k.hdr", "prior": "outdoor"}}
"""with --held-out: lights no rule of the init was designed on (a 12 and a 45 deg sun, a beach), on the arc and on
another object (HELD_OUT_OBJECT)"""
HELD_OUT_OBJECT = 11
"""the bumpy torus's object seed in the held-out scenes (the study's own: BASE's)"""
VIEWS = {"arc": {"views": 8, "held_out_every": 4, "width": 32, "height": 32, "arc_deg": 150.0,
                 "elevations_deg": (15.0, 40.0)},
         "around": {"views": 16, "held_out_every": 4, "width": 48, "height": 48, "arc_deg": 360.0,
                    "elevations_deg": (10.0, 35.0)}}
"""few small views on a 150 deg arc; more, larger views all around"""
BASE = {"shape": "bumpy_torus", "seed": 3, "spp": 128, "env_height": 32, "texture_size": 32,
        "roughness_variation": 0.0}


def scene_name(light: str, views: str, roughness: float) -> str:
    return f"torus_{light}_{views}_r{round(roughness * 100):03d}"


def study_scenes(panoramas: Path | None, held_out: bool = False) -> dict[str, dict[str, Any]]:
    """name -> synthetic capture settings (the real-light scenes only when `panoramas` is given); with `held_out`,
    the held-out scenes instead (HELD_OUT_LIGHTS on the arc, object seed HELD_OUT_OBJECT)."""
    from dpi.prior.panoramas import panorama_files

    files = {p.name: p for family in ("outdoor", "indoor") for p in panorama_files(panoramas, family, "held_out")} \
        if panoramas else {}
    lights = HELD_OUT_LIGHTS if held_out else LIGHTS
    views_of = {"arc": VIEWS["arc"]} if held_out else VIEWS
    base = {**BASE, "seed": HELD_OUT_OBJECT} if held_out else BASE
    scenes = {}
    for light, lit in lights.items():
        if "panorama" in lit:
            if lit["panorama"] not in files:
                continue
            lit = {"prior": lit["prior"], "environment": str(files[lit["panorama"]].resolve())}
        for views, seen in views_of.items():
            for r in ROUGHNESSES:
                scenes[scene_name(light, views, r)] = {**base, **seen, **lit, "roughness": r,
                                                       "metallic": 1.0 if r <= 0.1 else 0.0}
    return scenes


def reading_init(root: Path, scene: str, synth: dict, config: dict, reading: str) -> float:
    """The init of one reading alone (`init.reading`) in study folder `root`, made once; its closing loss."""
    import json

    from dpi.config.pipeline import Pipeline
    from dpi.io.layout import INIT, INIT_TRACE
    from dpi.solve.init import path_traced_init
    from dpi.solve.problem import SolveConfig
    from dpi.stages import load_problem
    from dpi.stages.seeding import seed_for

    folder = Job(root, scene, "", synth, INIT, "", 0, {}, config).layout.scene(scene).sample_dir(INIT)
    trace = folder / INIT_TRACE
    if not trace.exists():
        problem = load_problem(prepare_capture(root, scene, synth, threads=2), SolveConfig.from_config(config, 2))
        cfg = replace(Pipeline(config).init_settings, reading=reading)
        problem.save_decomposition(path_traced_init(problem, cfg, seed_for(scene, INIT), progress=False).kept, folder,
                                   trace_name=INIT_TRACE)
    return float(json.loads(trace.read_text())["info"]["readings"]["closing_loss"][reading])


def sample_row(job: Job) -> dict[str, Any]:
    """run_job's row of one sample with the reading it started from (the init's row: the reading it kept) and the
    init's readings record (its closing-loss ratio, the glossy reading's share)."""
    import json

    from dpi.io.layout import INIT

    row = run_job(job)
    scene = job.layout.scene(job.scene)
    info = json.loads(scene.sample_files(job.label, job.seed)["trace"].read_text())["info"]
    readings = json.loads(scene.sample_files(INIT)["trace"].read_text())["info"]["readings"]
    stopped = readings.get("stopped") is not None
    return {**row, "reading": info["reading"], "stopped": int(stopped),
            "ratio": readings["half_way_ratio"] if stopped else readings["ratio"],
            "log_bayes_factor": readings.get("log_bayes_factor", ""), "other_share": readings["other_share"]}


def group_row(scene: str, synth: dict, repeat: int, rows: list[dict[str, Any]], jobs: list[Job]) -> dict[str, Any]:
    """One scene repeat: its init and the mean of its samples' scores, the share of samples per reading, the
    samples' mean map's env PSNR, spread and calibration."""
    from dpi.capture import load_capture
    from dpi.evaluation.metrics import env_metrics
    from dpi.io.exr import read_exr
    from dpi.solve.spread import calibration, mean_log_map, normalized_env, sample_variance

    init, samples = rows[0], rows[1:]
    envs = [read_exr(j.layout.scene(j.scene).sample_files(j.label, j.seed)["env"]) for j in jobs[1:]]
    truth = read_exr(load_capture(jobs[0].layout.capture_dir(jobs[0].scene)).gt["envmap"])
    light, views = scene.split("_")[1:3]
    return {"scene": scene, "light": light, "views": views, "roughness": synth["roughness"],
            "metallic": synth["metallic"], "repeat": repeat, "samples": len(samples),
            "ratio": init["ratio"], "stopped": init["stopped"], "log_bayes_factor": init["log_bayes_factor"],
            "kept": init["reading"],
            "glossy_samples": sum(r["reading"] == "glossy" for r in samples) / len(samples),
            "init_novel_psnr": init["novel_psnr"], "init_env_psnr": init["env_psnr"], "init_seconds": init["seconds"],
            **{k: float(np.mean([r[k] for r in samples])) for k in ("novel_psnr", "env_psnr", "albedo_mse",
                                                                     "seconds")},
            "min_novel_psnr": min(r["novel_psnr"] for r in samples), "min_env_psnr": min(r["env_psnr"] for r in samples),
            "env_mean_psnr": env_metrics(mean_log_map(envs), truth)["env_psnr"],
            "env_sigma2_sample": sample_variance([normalized_env(e) for e in envs]),
            "calibration": calibration(envs, truth)}


def summary(rows: list[dict[str, Any]]) -> list[str]:
    """Per scene: means over repeats; then the metal / rough spread ratio per light and views."""
    lines = [f"{'scene':<24} {'n':>2} {'ratio':>6} {'glossy':>6} {'init views':>10} {'views':>6} {'min':>6} "
             f"{'init env':>8} {'env':>6} {'min':>6} {'mean map':>8} {'calib':>6} {'init s':>6}"]
    for scene in sorted({r["scene"] for r in rows}):
        sel = [r for r in rows if r["scene"] == scene]
        m = {k: float(np.mean([r[k] for r in sel])) for k in ("ratio", "glossy_samples", "init_novel_psnr",
                                                             "novel_psnr", "min_novel_psnr", "init_env_psnr",
                                                             "env_psnr", "min_env_psnr", "env_mean_psnr",
                                                             "calibration", "init_seconds")}
        lines.append(f"{scene:<24} {len(sel):>2} {m['ratio']:>6.2f} {m['glossy_samples']:>6.2f} "
                     f"{m['init_novel_psnr']:>10.2f} {m['novel_psnr']:>6.2f} {m['min_novel_psnr']:>6.2f} "
                     f"{m['init_env_psnr']:>8.2f} {m['env_psnr']:>6.2f} {m['min_env_psnr']:>6.2f} "
                     f"{m['env_mean_psnr']:>8.2f} {m['calibration']:>6.2f} {m['init_seconds']:>6.1f}")
    lines.append("metal / rough env sigma2_sample (roughness 0.05 over 0.8), per light, views and repeat:")
    for r in rows:
        if r["roughness"] <= 0.1:
            rough = [o for o in rows if (o["light"], o["views"], o["repeat"]) == (r["light"], r["views"], r["repeat"])
                     and o["roughness"] >= 0.8]
            if rough and rough[0]["env_sigma2_sample"] > 0:
                lines.append(f"  {r['light']} {r['views']} r{r['repeat']}: "
                             f"{r['env_sigma2_sample'] / rough[0]['env_sigma2_sample']:.2f}")
    return lines


def forced_readings(args: argparse.Namespace, config: dict, scenes: dict[str, dict]) -> None:
    """Each reading's init alone, and `--samples` dps samples from each: how the readings' rule was chosen."""
    from dpi.solve.init import READINGS

    dps_cfg = job_settings(config["method_params"].get("dps", {}))
    done = {(r["scene"], int(r["repeat"]), r["reading"], r["method"], int(r["seed"])) for r in read_rows(args.out, TEXT)}
    for base, synth0 in scenes.items():
        for repeat in range(args.repeats):
            scene, synth = repeat_scene(base, repeat), repeat_synth(synth0, repeat)
            for reading in READINGS:
                root = WORK / reading
                loss = reading_init(root, scene, synth, config, reading)
                for method, seed in [("init", 0)] + [("dps", 1000 * repeat + k) for k in range(args.samples)]:
                    if (base, repeat, reading, method, seed) in done:
                        continue
                    job = Job(root, scene, "readings", synth, method, "", seed, dps_cfg if method == "dps" else {},
                              config)
                    row = run_job(job)
                    light, views = base.split("_")[1:3]
                    append_row(args.out, {**row, "scene": base, "light": light, "views": views,
                                          "roughness": synth["roughness"], "metallic": synth["metallic"],
                                          "repeat": repeat, "reading": reading, "closing_loss": loss},
                               COLUMNS, settings_hash({"synth": synth, "job": job.settings_hash}))
                    print(f"{scene} {reading} {method} {seed}: views {row['novel_psnr']:.2f} env "
                          f"{row['env_psnr']:.2f} fit/truth {row['train_fit_over_truth']:.2f}", flush=True)


COST_COLUMNS = ("scene", "reading", "seconds", "stopped")


def init_costs(args: argparse.Namespace, config: dict, scenes: dict[str, dict]) -> None:
    """The init's wall time with both readings (auto) and with the rough reading alone (what the init cost before
    the readings), one after the other on the first repeat's captures, each alone on the machine."""
    import time

    from dpi.config.pipeline import Pipeline
    from dpi.io.layout import INIT
    from dpi.solve.init import path_traced_init
    from dpi.solve.problem import SolveConfig
    from dpi.stages import load_problem
    from dpi.stages.seeding import seed_for

    init = Pipeline(config).init_settings
    for base, synth0 in scenes.items():
        scene, synth = repeat_scene(base, 0), repeat_synth(synth0, 0)
        problem = load_problem(prepare_capture(WORK / "auto", scene, synth, threads=2), SolveConfig.from_config(config, 2))
        for reading in ("rough", "auto"):
            begin = time.perf_counter()
            result = path_traced_init(problem, replace(init, reading=reading), seed_for(scene, INIT), progress=False)
            row = {"scene": base, "reading": reading, "seconds": time.perf_counter() - begin,
                   "stopped": int(result.record.get("stopped") is not None)}
            append_row(args.out, row, COST_COLUMNS, settings_hash({"synth": synth, "init": vars(init)}))
            print(f"{base} {reading}: {row['seconds']:.1f} s", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--panoramas", type=Path, default=None)
    parser.add_argument("--scenes", nargs="*", default=None)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--samples", type=int, default=4)
    parser.add_argument("--jobs", type=int, default=2, help="samples drawn side by side (1 thread each)")
    parser.add_argument("--forced", action="store_true",
                        help="each reading alone, with its own samples (the rule's design data)")
    parser.add_argument("--cost", action="store_true",
                        help="time the init with both readings and with the rough one alone (the first repeat's "
                             "captures, one init at a time)")
    parser.add_argument("--held-out", action="store_true",
                        help="the held-out scenes (12 and 45 deg suns, a beach; another torus, on the arc) instead")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    config = workflow_config()
    scenes = {n: s for n, s in study_scenes(args.panoramas, args.held_out).items()
              if not args.scenes or n in args.scenes}
    if args.forced:
        args.out = args.out or CSV.with_name("readings_forced.csv")
        forced_readings(args, config, scenes)
        return
    if args.cost:
        args.out = args.out or CSV.with_name("readings_cost.csv")
        init_costs(args, config, scenes)
        return
    args.out = args.out or CSV
    dps_cfg = job_settings(config["method_params"].get("dps", {}))
    groups = {}
    for repeat in range(args.repeats):
        for base, synth0 in scenes.items():
            scene, synth = repeat_scene(base, repeat), repeat_synth(synth0, repeat)
            groups[(base, repeat)] = [Job(WORK / "auto", scene, "readings", synth, "init", "", 0, {}, config)] + [
                Job(WORK / "auto", scene, "readings", synth, "dps", "", 1000 * repeat + k, dps_cfg, config)
                for k in range(args.samples)]
    done = {(r["scene"], int(r["repeat"])) for r in read_rows(args.out, GROUP_TEXT)}
    with pool(max(args.jobs, 1)) as workers:
        for repeat in range(args.repeats):  # a whole repeat of every scene before the next
            todo = {key: jobs for key, jobs in groups.items() if key not in done and key[1] == repeat}
            list(workers.map(prepare_job, [jobs[0] for jobs in todo.values()]))
            for (base, _), jobs in todo.items():
                row = group_row(base, jobs[0].synth, repeat, list(workers.map(sample_row, jobs)), jobs)
                append_row(args.out, row, GROUP_COLUMNS, settings_hash([j.settings_hash for j in jobs]))
                print("  ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()),
                      flush=True)
    rows = [r for r in read_rows(args.out, GROUP_TEXT) if (r["scene"], int(r["repeat"])) in groups]
    print("\n".join(summary(rows)))


if __name__ == "__main__":
    main()
