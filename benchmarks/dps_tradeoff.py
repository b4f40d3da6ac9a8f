"""Run time of one `dps` sample against env-map, albedo and novel-view error, over steps and spp.

On the demo capture (captures/demo, made first if missing), with the demo's init (results/demo/init
when present, else computed here). Prints one row per (steps, spp) and the recommended CPU default:
the cheapest setting whose errors are within a tolerance of the best row.

    .venv/bin/python benchmarks/dps_tradeoff.py [--steps 1000 250 100 50] [--spp 4 16] [--threads 2]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from dpi.capture import load_capture
from dpi.evaluate import evaluate_sample
from dpi.prior.sample import load_default_prior
from dpi.render import RenderSettings
from dpi.solve.decomposition import Decomposition
from dpi.solve.dps import DPSConfig, dps_sample
from dpi.solve.init import path_traced_init
from dpi.solve.optimize import OptimizeConfig
from dpi.solve.problem import InverseProblem, ProblemSettings
from dpi.synth.capture import SynthConfig, make_synthetic_capture

ROOT = Path(__file__).resolve().parent.parent
DEMO = ROOT / "captures" / "demo"
DEMO_INIT = ROOT / "results" / "demo" / "init"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, nargs="+", default=[1000, 250, 100, 50])
    parser.add_argument("--spp", type=int, nargs="+", default=[4, 16])
    parser.add_argument("--refine-iterations", type=int, default=100)
    parser.add_argument("--env-height", type=int, default=16)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    if not (DEMO / ".synth.json").exists():
        make_synthetic_capture(DEMO, SynthConfig(), threads=args.threads)
    capture = load_capture(DEMO)
    settings = ProblemSettings(env_height=args.env_height, texture_size=64)
    prior = load_default_prior(capture.options.get("prior", "outdoor"))
    if (DEMO_INIT / "log.json").exists():
        init = Decomposition.load(DEMO_INIT, settings.texture_size)
    else:
        problem = InverseProblem(capture, settings, RenderSettings(spp=16, threads=args.threads))
        init = path_traced_init(problem, OptimizeConfig(iterations=200), seed=0, progress=False)

    print(f"demo scene, {len(capture.train_views)} training / {len(capture.held_out_views)} held-out views, "
          f"env {args.env_height}x{2 * args.env_height}, refine {args.refine_iterations} it, {args.threads} threads")
    header = f"{'steps':>6} {'spp':>4} {'s/sample':>9} {'env PSNR':>9} {'albedo MSE':>11} {'view PSNR':>10}"
    print(header)
    rows = []
    for steps in args.steps:
        for spp in args.spp:
            problem = InverseProblem(capture, settings, RenderSettings(spp=spp, threads=args.threads))
            cfg = DPSConfig(steps=steps, refine_iterations=args.refine_iterations)
            start = time.perf_counter()
            result = dps_sample(problem, prior, init, cfg, seed=args.seed, progress=False).decomposition
            seconds = time.perf_counter() - start
            m = evaluate_sample(problem, result, spp=64, seed=1, seconds=seconds)
            rows.append((steps, spp, seconds, m["env_psnr"], m["albedo_mse"], m["novel_psnr"]))
            print(f"{steps:>6} {spp:>4} {seconds:>9.1f} {m['env_psnr']:>9.2f} {m['albedo_mse']:>11.5f} "
                  f"{m['novel_psnr']:>10.2f}", flush=True)
    best_env = max(r[3] for r in rows)
    best_view = max(r[5] for r in rows)
    good = [r for r in rows if r[3] >= best_env - 1.0 and r[5] >= best_view - 1.0]
    pick = min(good, key=lambda r: r[2])
    print(f"recommended CPU default: steps={pick[0]}, spp={pick[1]} ({pick[2]:.0f} s/sample; within 1 dB of the "
          f"best env and view PSNR)")


if __name__ == "__main__":
    main()
