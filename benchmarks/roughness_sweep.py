"""Env-map diversity of `dps` samples against material roughness (the paper's Fig. 9 curve).

Renders one object at each roughness under the same procedural sky, runs the initialisation and
N dps samples with the shipped outdoor prior, and prints env-map sigma2_sample per roughness.

    .venv/bin/python benchmarks/roughness_sweep.py [--roughness 0.05 0.2 0.5 0.9] [--samples 3]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace

from dpi.prior.sample import load_default_prior
from dpi.studies import SweepSettings, roughness_sweep


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--roughness", type=float, nargs="+", default=[0.05, 0.2, 0.5, 0.9])
    parser.add_argument("--samples", type=int, default=3)
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()

    defaults = SweepSettings()
    settings = replace(defaults, samples=args.samples, dps=replace(defaults.dps, steps=args.steps))
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        rows = roughness_sweep(args.roughness, load_default_prior("outdoor"), tmp, settings, args.threads)
    print(f"{settings.samples} dps samples per roughness, {args.steps} steps, "
          f"{time.perf_counter() - start:.0f} s in all")
    print(f"{'roughness':>9} {'metallic':>8} {'env sigma2_sample':>18}")
    for r in rows:
        print(f"{r['roughness']:>9.3f} {r['metallic']:>8.1f} {r['env_sigma2_sample']:>18.5f}")


if __name__ == "__main__":
    main()
