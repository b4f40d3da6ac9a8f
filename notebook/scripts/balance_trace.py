"""Where a dps sample's broad balance of light (sky against ground, side against side) is lost (issue 77).

    .venv/bin/python notebook/scripts/balance_trace.py --panoramas DIR [--scenes ...] [--seeds 0 1 2]
        [--dps NAME:key=value,... ...] [--out notebook/results/balance_trace.csv]

For each design scene (dpi.studies.scenes.DEV_SCENES: other objects and held-out panoramas than the studies') and
seed, each dps variant (the configured sampler as `proximal`, plus `--dps` variants such as materials held at the
init's: `held:lr_albedo=1e-9,refine.lr_texels=1e-9`) draws one sample through the workflow's sample stage while
dpi.solve.dps.loop.dps_phases yields the map at every stage: the network's x0_hat and the solved map of each reverse
step, the loop's map, after keep_what_the_views_see, and after the refinement. Each row is one (scene, variant, seed,
stage, step) with the map's log error at 2 and 8 rows against the truth (dpi.evaluation.metrics.balance_error); the
init's map is the `init` stage. The CSV's rows of the scenes and variants run are replaced, the others kept; it
prints the means per variant and stage, relative to the init's error of the same scene.
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from dataclasses import replace
from pathlib import Path

import numpy as np

from dpi.capture import read_capture_json, read_ground_truth
from dpi.evaluation.metrics import BALANCE_ROWS, balance_error
from dpi.io.exr import read_exr
from dpi.io.layout import INIT
from dpi.solve.dps.loop import MAP_PHASES
from dpi.solve.methods import dps_phases_of
from dpi.stages.inverse import sample_job
from dpi.studies.engine import (claim_sample_dir, dps_variants, method_jobs, prepare_job, read_rows, work_dir, workflow_config, write_rows)
from dpi.studies.scenes import DEV_SCENES, real_light_scenes

STAGES = ("init", *MAP_PHASES)
TEXT = ("scene", "group", "variant", "stage", "label")
"""the CSV's text columns"""
SHOWN_STEPS = (0.0, 0.5, 1.0)
"""x0_hat and solved are shown at these shares of the loop's steps"""


def errors(env: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """The map's log balance error at each of BALANCE_ROWS rows (`err_2`, `err_8`)."""
    return {f"err_{rows}": round(balance_error(env, truth, rows), 4) for rows in BALANCE_ROWS}


def trace_job(job, truth: np.ndarray) -> list[dict]:
    """Draw the job's sample phase by phase (its sample stage's inputs, nothing written); one row per map it yields."""
    rows: list[dict] = []
    claim_sample_dir(job)
    stage = job.stage_job(threads=1)
    _, sample = sample_job(stage)
    for phase in dps_phases_of(sample):
        step = phase["record"]["step"] if phase["phase"] == "step" else None
        maps = {name: phase[name] for name in ("x0_hat", "solved")} if step is not None \
            else {phase["phase"]: phase["env"]}
        for stage_name, env in maps.items():
            if env is not None:
                rows.append({"stage": stage_name, "step": step if step is not None else phase_steps(rows),
                             **errors(env.detach().double().numpy(), truth)})
    return [{"scene": job.scene, "group": job.group, "variant": job.sampler, "seed": job.seed, **r} for r in rows]


def phase_steps(rows: list[dict]) -> int:
    """The step number a phase after the loop is recorded at: the loop's steps."""
    return max((int(r["step"]) for r in rows if r["stage"] in ("x0_hat", "solved")), default=-1) + 1


def labelled(rows: list[dict], init: dict[str, float]) -> list[dict]:
    """One sample's rows with their table `label` (x0_hat and solved at SHOWN_STEPS of the loop, as `x0_hat@0.5`;
    empty for the other steps; the later stages by name) and each error over the init's (`over_init_2`, ...)."""
    end = max((int(r["step"]) for r in rows if r["stage"] in ("x0_hat", "solved")), default=0)
    shown = {round(share * end): f"{share:.1f}" for share in SHOWN_STEPS}
    out = []
    for r in rows:
        step = int(r["step"])
        label = r["stage"] if r["stage"] not in ("x0_hat", "solved") else \
            f"{r['stage']}@{shown[step]}" if step in shown else ""
        out.append({**r, "label": label, **{f"over_init_{k}": round(r[f"err_{k}"] / max(init[f"err_{k}"], 1e-6), 4)
                                            for k in BALANCE_ROWS}})
    return out


def summary(rows: list[dict]) -> list[str]:
    """Mean error (and over the init's) per scene group, variant and labelled stage."""
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for r in rows:
        if r["label"]:
            groups[(r["group"], r["variant"], r["label"])].append(r)
    columns = [f"{name}_{k}" for k in BALANCE_ROWS for name in ("err", "over_init")]
    lines = [f"{'group':<12} {'variant':<14} {'stage':<12} {'n':>3} " + " ".join(f"{c:>12}" for c in columns)]
    for (group, variant, label), sel in sorted(groups.items(), key=lambda kv: (
            kv[0][0], kv[0][1] != "init", kv[0][1], STAGES.index(kv[0][2].split("@")[0]), kv[0][2])):
        lines.append(f"{group:<12} {variant:<14} {label:<12} {len(sel):>3} "
                     + " ".join(f"{np.mean([r[c] for r in sel]):>12.3f}" for c in columns))
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--panoramas", type=Path, required=True, help="folder holding the manifest's panoramas")
    parser.add_argument("--scenes", nargs="*", default=None, choices=list(DEV_SCENES), help="default: every one")
    parser.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2])
    parser.add_argument("--dps", nargs="*", default=[], metavar="NAME:key=value,...", help="dps variants")
    parser.add_argument("--variants", nargs="*", default=None, help="variant labels to run (default: proximal and "
                                                                    "the --dps ones)")
    parser.add_argument("--work", type=Path, default=work_dir("balance_trace"), help="study folder")
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parents[1] / "results" / "balance_trace.csv")
    parser.add_argument("--summary", action="store_true", help="print the CSV's table without drawing")
    args = parser.parse_args()
    if args.summary:
        print("\n".join(summary(read_rows(args.out, TEXT))))
        return
    config = workflow_config()
    variants = dps_variants(config, args.dps)
    wanted = args.variants or ["proximal", *(spec.partition(":")[0] for spec in args.dps)]
    scenes = {name: scene for name, scene in real_light_scenes(args.panoramas, DEV_SCENES).items()
              if name in (args.scenes or DEV_SCENES)}
    rows = [r for r in read_rows(args.out, TEXT) if r["scene"] not in scenes or r["variant"] not in wanted]
    inits = {r["scene"]: r for r in rows if r["stage"] == "init"}
    for job in method_jobs(args.work, scenes, ["dps"], args.seeds, config, variants, wanted):
        prepare_job(job)
        scene = job.layout.scene(job.scene)
        truth = read_ground_truth(read_capture_json(scene.capture_json).gt["envmap"], "envmap")
        if job.scene not in inits:
            init = {"scene": job.scene, "group": job.group, "variant": "init", "seed": 0, "stage": "init", "step": 0,
                    **errors(read_exr(scene.sample_files(INIT)["env"]), truth)}
            inits[job.scene] = init
            rows.extend(labelled([init], init))
        rows.extend(labelled(trace_job(replace(job, rerun=True), truth), inits[job.scene]))
        write_rows(args.out, rows, settings="")
        print(f"{job.scene} {job.sampler} seed {job.seed}: done", flush=True)
    print("\n".join(summary(rows)))


if __name__ == "__main__":
    main()
