"""Realism of a prior against real HDR panoramas it never trained on.

    .venv/bin/python benchmarks/priors/prior_realism.py --panoramas DIR [--checkpoint dpi/data/models/outdoor_32x64.pt]

DIR holds the panoramas of the manifest (dpi/data/panoramas.csv; `dpi panorama-set` explains). Per map
kind (the manifest's held-out real maps, its training real maps, freshly generated procedural maps, the
prior's own unconditional samples; with `--reni` or `--gan`, a learned baseline's unconditional samples instead,
dpi train-reni / train-gan)
it prints and appends to benchmarks/priors/prior_realism.csv:
the prior's denoising error (dpi.evaluation.naturalness: the mean eps-prediction MSE, lower is more
likely under the prior), NIQE (dpi.evaluation.niqe.env_niqe, lower is more photo-like) and the realism distance
of the kind's maps to the held-out real maps (dpi.evaluation.realism; lower is closer to them). It writes
a grid of samples (top rows) above the held-out real maps (bottom row) as PNG next to the CSV.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch

from dpi.evaluation.naturalness import naturalness, prior_image
from dpi.evaluation.niqe import env_niqe
from dpi.evaluation.realism import realism_distance
from dpi.prior.data import read_panorama
from dpi.prior.panoramas import panorama_files
from dpi.prior.gan import load_gan
from dpi.prior.reni import load_reni
from dpi.prior.sample import DEFAULT_MODELS, draw_samples, load_prior, write_grid
from dpi.render import backend
from dpi.studies.engine import append_row, settings_hash
from dpi.worlds.families import checked_envmaps

RESULTS = Path(__file__).resolve().parent
HELD_OUT_SEED = 1000
"""seed of the procedural maps (the shipped priors trained on seed 0)"""
COLUMNS = ("checkpoint", "family", "kind", "maps", "denoising_mse", "denoising_mse_std", "niqe", "niqe_std", "realism")


def row(kind: str, maps: list[np.ndarray], prior, checkpoint: str, held_out: list[np.ndarray]) -> dict:
    """Denoising error and NIQE of HDR maps (H, W, 3) under `prior` (mean and std over the maps), and their realism
    distance to the held-out real maps (none for those maps themselves)."""
    mse = np.array([-naturalness(m, prior) for m in maps])
    niqe = np.array([env_niqe(m) for m in maps])
    return {"checkpoint": Path(checkpoint).name, "family": prior.family, "kind": kind,
            "maps": len(maps),
            "denoising_mse": round(float(mse.mean()), 5), "denoising_mse_std": round(float(mse.std()), 5),
            "niqe": round(float(niqe.mean()), 3), "niqe_std": round(float(niqe.std()), 3),
            "realism": "" if maps is held_out else round(realism_distance(maps, held_out), 4)}


def baseline_samples(reni: str | None, gan: str | None, family: str, count: int, height: int) -> torch.Tensor:
    """`count` unconditional samples (count, 3, H, 2H) in the prior's encoding of a RENI decoder (its latent prior's
    draws) or a GAN generator (z ~ N(0, I)), seed 0."""
    generator = torch.Generator().manual_seed(0)
    with torch.no_grad():
        if reni:
            model = load_reni(reni, family=family)
            return model.decoder.decode(model.draw(count, generator), height).permute(0, 3, 1, 2).clamp(-1, 1)
        model = load_gan(gan, family=family, height=height)
        return model.generator(torch.randn(count, model.generator.network.latent, generator=generator))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--panoramas", required=True, help="folder holding the manifest's panoramas")
    parser.add_argument("--family", default="outdoor", choices=sorted(DEFAULT_MODELS))
    parser.add_argument("--checkpoint", default=None, help="prior checkpoint (default: the family's shipped one)")
    parser.add_argument("--reni", default=None, help="score this RENI decoder's samples (its prior's draws), one row")
    parser.add_argument("--gan", default=None, help="score this GAN generator's samples, one row")
    parser.add_argument("--count", type=int, default=16, help="procedural maps and samples")
    parser.add_argument("--steps", type=int, default=50, help="respaced steps of the samples")
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    backend.mitsuba(threads=args.threads)
    checkpoint = args.checkpoint or str(DEFAULT_MODELS[args.family])
    prior = load_prior(checkpoint)
    start = time.perf_counter()
    real = {split: [read_panorama(p) for p in panorama_files(args.panoramas, args.family, split)]
            for split in ("held_out", "train")}
    if args.reni or args.gan:
        x, checkpoint, kinds = baseline_samples(args.reni, args.gan, args.family, args.count, prior.height), \
            args.reni or args.gan, ()
    else:
        procedural, _ = checked_envmaps(args.family, args.count, 2 * prior.height, seed=HELD_OUT_SEED, progress=False)
        x = draw_samples(prior, args.count, args.steps, seed=0)
        kinds = (("real_held_out", real["held_out"]), ("real_train", real["train"]), ("procedural", procedural))
    samples = [prior.encoding.to_radiance(xi).permute(1, 2, 0).numpy() for xi in x]
    rows = [row(kind, maps, prior, checkpoint, real["held_out"]) for kind, maps in (*kinds, ("samples", samples))]
    name = Path(checkpoint).stem
    columns = 4
    held = torch.stack([prior_image(m, prior) for m in real["held_out"]])
    tiles = torch.cat([x[: columns * max(1, (args.count // columns) - 1)], held])
    write_grid(RESULTS / f"prior_realism_{name}.png", tiles, columns=columns)
    settings = settings_hash({"family": args.family, "count": args.count, "steps": args.steps,
                              "seed": HELD_OUT_SEED, "held_out": sorted(p.name for p in panorama_files(
                                  args.panoramas, args.family, "held_out"))})
    for r in rows:
        append_row(RESULTS / "prior_realism.csv", r, COLUMNS, settings)
    print(f"{'kind':<14} {'maps':>4} {'denoising MSE':>16} {'NIQE':>14} {'realism':>8}   "
          f"({name}, {time.perf_counter() - start:.0f} s)")
    for r in rows:
        print(f"{r['kind']:<14} {r['maps']:>4} {r['denoising_mse']:>9.4f} +- {r['denoising_mse_std']:<6.4f}"
              f"{r['niqe']:>7.2f} +- {r['niqe_std']:<5.2f} {r['realism'] or '-':>8}")


if __name__ == "__main__":
    main()
