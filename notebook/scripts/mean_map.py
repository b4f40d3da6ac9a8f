"""How near the truth the samples' geometric mean map is, against one sample (dpi.solve.spread.mean_log_map).

A calibrated sample is as far from the truth as from another sample, so each one pays env accuracy for a
spread that covers its error; what the samples agree on, their mean in log radiance, need not. For every
scene of a study (the posterior or the calibration study's results) and each method folder with 2 or
more samples, this scores the samples' env maps and their mean map against the scene's true map with the
evaluation's env PSNR / SSIM, and prints the means per method folder.

    .venv/bin/python notebook/scripts/mean_map.py results/benchmarks/posterior_study [--methods dps_proximal ...]
        [--scenes blob_sun ...] [--out CSV]
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import numpy as np

from dpi.capture import read_capture_json, read_ground_truth
from dpi.evaluation.metrics import env_metrics
from dpi.io.exr import read_exr
from dpi.io.layout import ENV_FILE
from dpi.solve.spread import mean_log_map
from dpi.studies.engine import settings_hash, write_rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("root", type=Path, help="a study folder (it holds results/{scene}/...)")
    parser.add_argument("--methods", nargs="*", default=None, help="method folders (default: all)")
    parser.add_argument("--scenes", nargs="*", default=None, help="scenes (default: all with a true map)")
    parser.add_argument("--out", type=Path, default=None, help="CSV: scene, method, samples, env PSNR / SSIM")
    args = parser.parse_args()

    rows = []
    for capture_json in sorted(args.root.glob("results/*/capture.json")):
        scene = capture_json.parent.name
        truth = read_capture_json(capture_json).gt.get("envmap")
        if truth is None or (args.scenes is not None and scene not in args.scenes):
            continue
        reference = read_ground_truth(truth, "envmap")
        for method_dir in sorted(p for p in capture_json.parent.iterdir()
                                 if p.is_dir() and (args.methods is None or p.name in args.methods)):
            envs = [read_exr(f) for f in sorted(method_dir.glob(f"*/{ENV_FILE}"))]
            if len(envs) < 2:
                continue
            single = [env_metrics(env, reference) for env in envs]
            mean = env_metrics(mean_log_map(envs), reference)
            rows.append({"scene": scene, "method": method_dir.name, "samples": len(envs),
                         "sample_env_psnr": np.mean([s["env_psnr"] for s in single]),
                         "sample_env_ssim": np.mean([s["env_ssim"] for s in single]),
                         "mean_env_psnr": mean["env_psnr"], "mean_env_ssim": mean["env_ssim"]})
    if args.out:
        write_rows(args.out, rows, settings_hash({"methods": args.methods, "scenes": args.scenes}))
    groups = defaultdict(list)
    for row in rows:
        groups[row["method"]].append(row)
    print(f"{'method':<18} {'scenes':>6} {'one sample: env PSNR':>21} {'SSIM':>6} {'mean map: env PSNR':>19} {'SSIM':>6}")
    for method, group in sorted(groups.items()):
        m = {k: np.mean([r[k] for r in group]) for k in ("sample_env_psnr", "sample_env_ssim", "mean_env_psnr",
                                                       "mean_env_ssim")}
        print(f"{method:<18} {len(group):>6} {m['sample_env_psnr']:>21.2f} {m['sample_env_ssim']:>6.3f} "
              f"{m['mean_env_psnr']:>19.2f} {m['mean_env_ssim']:>6.3f}")


if __name__ == "__main__":
    main()
