"""How real and how well spread the posterior study's env maps are, method by method, on its real-light scenes.

    .venv/bin/python notebook/scripts/light_realism.py --panoramas DIR [--work results/benchmarks/posterior_study]
        [--study benchmarks/posterior/posterior.csv ...] [--out notebook/results/light_realism.csv]

For every (scene, method, sampler) the posterior study drew on a real-light scene (dpi.studies.scenes.
REAL_LIGHT_SCENES), a design scene (DEV_SCENES, `posterior_study.py --dev`) or a held-out one (HELD_OUT_LIGHT_SCENES,
`--held-out`), over its seeds:
- realism: each sample's realism distance (dpi.evaluation.realism) to the manifest's held-out real panoramas of
  the scene's family less the scene's own (a map that copies the truth should not pass for realism; its accuracy
  is env PSNR's business), mean and std over the samples;
- calibration (dpi.solve.spread.calibration: ~1 when the truth looks like one more sample), and the same of the
  maps shrunk to COARSE_ROWS rows: the light's broad balance (sky against ground, one side against another);
- env PSNR / SSIM of the samples' mean map (dpi.solve.spread.mean_log_map) against the truth;
- how concentrated the light is (`peak_share`: the brightest 1 % of texels' share of the energy, at the realism's
  REALISM_HEIGHT rows), the samples' mean beside the truth's;
- the light's broad balance against the init's: the log error at BALANCE_ROWS rows (dpi.evaluation.metrics) of the
  samples' mean map and of the worst sample, each over the init's (`balance_mean_2`, `balance_worst_8`, ...).
Rows go to the CSV, rewritten whole; it prints the means per group, method and sampler.
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import numpy as np
import torch

from dpi.capture import read_capture_json, read_ground_truth
from dpi.evaluation.metrics import BALANCE_ROWS, balance_error, env_metrics, resize_image
from dpi.evaluation.realism import REALISM_HEIGHT, patches, sliced_wasserstein
from dpi.io.exr import read_exr
from dpi.io.layout import INIT, Layout
from dpi.light.envmap import top_energy_share
from dpi.prior.data import read_panorama
from dpi.prior.panoramas import panorama_files
from dpi.solve.spread import calibration, mean_log_map
from dpi.studies.engine import read_rows, results_csv, sample_label, work_dir, write_rows
from dpi.studies.scenes import DEV_SCENES, HELD_OUT_LIGHT_SCENES, REAL_LIGHT_SCENES

SCENES = {**REAL_LIGHT_SCENES, **DEV_SCENES, **HELD_OUT_LIGHT_SCENES}
COARSE_ROWS = 2
"""rows of the maps whose calibration is the broad balance's"""
PEAK_FRACTION = 0.01
"""the brightest texels whose share of the energy says how concentrated a map's light is"""
BALANCE = tuple(f"balance_{which}_{rows}" for which in ("mean", "worst") for rows in BALANCE_ROWS)
"""the balance columns: mean map's and worst sample's log error at each of BALANCE_ROWS rows over the init's"""
METRICS = ("realism", "realism_std", "calibration", "calibration_coarse", "env_mean_psnr", "env_mean_ssim",
           "env_psnr", "peak_share", "peak_share_truth", *BALANCE)


def coarse(env: np.ndarray) -> np.ndarray:
    """The map shrunk to COARSE_ROWS rows (area average)."""
    return resize_image(env, COARSE_ROWS, 2 * COARSE_ROWS)


def peak_share(env: np.ndarray) -> float:
    """dpi.light.envmap.top_energy_share of the map's PEAK_FRACTION at REALISM_HEIGHT rows (area average)."""
    return top_energy_share(resize_image(env, REALISM_HEIGHT, 2 * REALISM_HEIGHT), PEAK_FRACTION)


def balance_ratios(envs: list[np.ndarray], init: np.ndarray | None, truth: np.ndarray) -> dict[str, float]:
    """The BALANCE columns: the samples' mean map's and their worst's log error at each of BALANCE_ROWS rows over
    the init's (nan without an init)."""
    out = {}
    for rows in BALANCE_ROWS:
        reference = balance_error(init, truth, rows) if init is not None else float("nan")
        errors = [balance_error(env, truth, rows) for env in envs]
        out[f"balance_mean_{rows}"] = round(balance_error(mean_log_map(envs), truth, rows) / reference, 3)
        out[f"balance_worst_{rows}"] = round(max(errors) / reference, 3)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--panoramas", type=Path, required=True, help="folder holding the manifest's panoramas")
    parser.add_argument("--work", type=Path, default=work_dir("posterior_study"), help="the posterior study's folder")
    parser.add_argument("--study", type=Path, nargs="+", default=[results_csv("posterior")],
                        help="the posterior study's CSVs (and dev CSVs drawn in its folder): which samples exist, with "
                             "their method and sampler")
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parents[1] / "results" / "light_realism.csv")
    args = parser.parse_args()
    layout = Layout.of_study(args.work)
    clouds = {family: {path.name: patches(read_panorama(path))
                       for path in panorama_files(args.panoramas, family, "held_out")}
              for family in ("outdoor", "indoor")}
    samples: dict[tuple, list[Path]] = defaultdict(list)
    for r in (row for study in args.study for row in read_rows(study)):
        if r["scene"] in SCENES and r["method"] != "init":
            env = layout.scene(r["scene"]).sample_files(sample_label(r["method"], r["sampler"]), int(r["seed"]))["env"]
            key = (r["scene"], r["group"], r["method"], r["sampler"])
            if env.exists() and env not in samples[key]:
                samples[key].append(env)
    rows = []
    for (scene, group, method, sampler), files in sorted(samples.items()):
        synth = SCENES[scene][1]
        references = torch.cat([c for name, c in clouds[synth["prior"]].items() if name != synth.get("panorama")])
        envs = [read_exr(f) for f in files]
        truth = read_ground_truth(read_capture_json(layout.scene(scene).capture_json).gt["envmap"], "envmap")
        distances = [sliced_wasserstein(patches(env), references) for env in envs]
        mean = env_metrics(mean_log_map(envs), truth)
        init_env = layout.scene(scene).sample_files(INIT)["env"]
        init = read_exr(init_env) if init_env.exists() else None
        rows.append({"scene": scene, "group": group, "method": method, "sampler": sampler, "samples": len(envs),
                     "realism": round(float(np.mean(distances)), 4), "realism_std": round(float(np.std(distances)), 4),
                     "calibration": round(calibration(envs, truth), 3),
                     "calibration_coarse": round(calibration([coarse(e) for e in envs], coarse(truth)), 3),
                     "env_mean_psnr": round(mean["env_psnr"], 3),
                     "env_mean_ssim": round(mean["env_ssim"], 4),
                     "env_psnr": round(float(np.mean([env_metrics(e, truth)["env_psnr"] for e in envs])), 3),
                     "peak_share": round(float(np.mean([peak_share(e) for e in envs])), 4),
                     "peak_share_truth": round(peak_share(truth), 4), **balance_ratios(envs, init, truth)})
    write_rows(args.out, rows, settings="")
    print(f"{'group':<12} {'method':<12} {'sampler':<24} {'n':>3} " + " ".join(f"{m:>14}" for m in METRICS))
    for key in sorted({(r["group"], r["method"], r["sampler"]) for r in rows}):
        sel = [r for r in rows if (r["group"], r["method"], r["sampler"]) == key]
        cells = [f"{np.nanmean([r[m] for r in sel]):.3f}" for m in METRICS]
        print(f"{key[0]:<12} {key[1]:<12} {key[2]:<24} {len(sel):>3} " + " ".join(f"{c:>14}" for c in cells))


if __name__ == "__main__":
    main()
