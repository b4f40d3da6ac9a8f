"""Sample quality of the default priors: distribution distance, dynamic range, wrap seam, sampling time.

    .venv/bin/python benchmarks/priors/prior_quality.py [--families outdoor indoor] [--count 64] [--steps 100]

Features (no download): hand-crafted statistics of each prior-space map: mean colour of 8
latitude bands, a 2x4 colour thumbnail, an 8-bin luminance histogram, an 8-bin histogram of
gradient magnitudes and per-channel standard deviations (67 numbers). The distance is the Frechet
distance between Gaussians fitted to these features (FID's formula, our features): "FSD".
Held-out maps are freshly generated with a seed the training data never used. References:
training maps vs held-out (the floor) and a Gaussian-blurred noise baseline (far away).
The wrap seam is the mean |x[..., 0] - x[..., W-1]| divided by the mean difference of
neighbouring interior columns (1 = as smooth as the rest; paper Fig. 12 ablation).
Dynamic range: per map, the energy share of its brightest 0.5 % texels (solid-angle weighted: a
sun carries about half) and max / median luminance, for samples against held-out maps.
Also writes dpi/data/models/{family}_samples.png: samples (left) next to their nearest training map
(right, nearest over all azimuth rolls and flips), shown as radiance (median-normalised, Reinhard,
sRGB), and dpi/data/models/{family}_dynamic_range.png: histograms of log10(texel luminance / median) of
samples and held-out maps.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch
from scipy import linalg
from torch.nn import functional as F

from dpi.io.images import linear_to_srgb, luminance
from dpi.light.envmap import top_energy_share
from dpi.light.tonecurve import Encoding
from dpi.prior.data import median_target, read_dataset, to_prior_space
from dpi.prior.sample import DEFAULT_MODELS, MODELS_DIR, draw_samples, load_prior, write_grid
from dpi.render import backend
from dpi.worlds.families import checked_envmaps

HELD_OUT_SEED = 1000


def features(x: torch.Tensor) -> np.ndarray:
    """Hand-crafted statistics (B, 67) of prior-space maps (B, 3, H, W)."""
    b = x.shape[0]
    bands = F.adaptive_avg_pool2d(x, (8, 1)).reshape(b, -1)
    thumb = F.adaptive_avg_pool2d(x, (2, 4)).reshape(b, -1)
    lum = x.mean(1)
    lum_hist = torch.stack([torch.histc(v, 8, -1, 1) / v.numel() for v in lum])
    grad = (lum.diff(dim=-1)[:, :-1].abs() + lum.diff(dim=-2)[..., :-1].abs())
    grad_hist = torch.stack([torch.histc(v, 8, 0, 0.5) / v.numel() for v in grad])
    std = x.std(dim=(2, 3))
    return torch.cat([bands, thumb, lum_hist, grad_hist, std], dim=1).double().numpy()


def frechet_distance(a: np.ndarray, b: np.ndarray) -> float:
    """||mu_a - mu_b||^2 + Tr(S_a + S_b - 2 (S_a S_b)^(1/2)) of Gaussians fitted to feature rows."""
    mu_a, mu_b = a.mean(0), b.mean(0)
    s_a, s_b = np.cov(a, rowvar=False), np.cov(b, rowvar=False)
    covmean = linalg.sqrtm(s_a @ s_b)
    return float(((mu_a - mu_b) ** 2).sum() + np.trace(s_a + s_b - 2 * np.real(covmean)))


def seam_ratio(x: torch.Tensor) -> float:
    """Mean wrap-seam jump divided by the mean jump between neighbouring interior columns."""
    seam = (x[..., 0] - x[..., -1]).abs().mean()
    interior = (x[..., 1:] - x[..., :-1]).abs().mean()
    return float(seam / interior)


def blurred_noise(count: int, height: int, seed: int) -> torch.Tensor:
    """A far-away baseline: smooth random images in [-1, 1]."""
    g = torch.Generator().manual_seed(seed)
    noise = F.interpolate(torch.rand(count, 3, 4, 8, generator=g) * 2 - 1, size=(height, 2 * height), mode="bilinear")
    return noise.clamp(-1, 1)


def nearest_training_maps(samples: torch.Tensor, train: torch.Tensor) -> torch.Tensor:
    """For each sample, the training map (any azimuth roll or flip) with the smallest L2 distance."""
    width = train.shape[-1]
    best = torch.full((len(samples),), float("inf"))
    out = torch.zeros_like(samples)
    flat_s = samples.reshape(len(samples), -1)
    for variant in (train, train.flip(-1)):
        for shift in range(width):
            cand = torch.roll(variant, shift, dims=-1).reshape(len(train), -1)
            d = torch.cdist(flat_s, cand)
            value, idx = d.min(dim=1)
            better = value < best
            best = torch.where(better, value, best)
            out[better] = torch.roll(variant[idx[better]], shift, dims=-1)
    return out


def held_out_maps(family: str, count: int, height: int, encoding: Encoding) -> torch.Tensor:
    """Freshly generated maps of the family (a seed the training data never used), in prior space."""
    maps, _ = checked_envmaps(family, count, height, seed=HELD_OUT_SEED, progress=False)
    target = median_target(family, encoding)
    return torch.stack([to_prior_space(torch.from_numpy(m).permute(2, 0, 1), encoding, target) for m in maps])


def luminance_over_median(x: torch.Tensor, encoding: Encoding) -> torch.Tensor:
    """Texel luminance over the map's median (B, H, W) of prior-space maps (B, 3, H, W)."""
    lum = luminance(encoding.to_radiance(x).permute(0, 2, 3, 1))
    return lum / lum.flatten(1).median(dim=1).values.clamp_min(1e-30)[:, None, None]


def top_energy_shares(x: torch.Tensor, encoding: Encoding) -> np.ndarray:
    """dpi.light.envmap.top_energy_share of each prior-space map (B, 3, H, W)."""
    radiance = encoding.to_radiance(x).permute(0, 2, 3, 1).numpy()
    return np.array([top_energy_share(env) for env in radiance])


def radiance_display(x: torch.Tensor, encoding: Encoding) -> torch.Tensor:
    """Prior-space maps as viewers see radiance, back in [-1, 1] for the grid: median-normalised to
    0.18, Reinhard, sRGB."""
    radiance = encoding.to_radiance(x)
    lum = luminance(radiance.permute(0, 2, 3, 1)).flatten(1).median(dim=1).values.clamp_min(1e-30)
    scaled = radiance * (0.18 / lum)[:, None, None, None]
    srgb = torch.from_numpy(linear_to_srgb((scaled / (1 + scaled)).numpy()))
    return srgb * 2 - 1


def dynamic_range_plot(path: Path, family: str, samples: torch.Tensor, held: torch.Tensor, encoding: Encoding) -> None:
    """Histograms of log10(luminance / median) over all texels of samples and held-out maps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.2))
    bins = np.linspace(-3, 5, 65)
    for maps, label in ((held, "held-out maps"), (samples, "prior samples")):
        values = np.log10(luminance_over_median(maps, encoding).flatten().clamp_min(1e-3).numpy())
        ax.hist(values, bins=bins, histtype="step", density=True, log=True, label=label)
    ax.set_xlabel("log10(texel luminance / map median)")
    ax.set_ylabel("density")
    ax.set_title(f"{family}: dynamic range of {len(samples)} samples and {len(held)} held-out maps")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def pair_grid(samples: torch.Tensor, nearest: torch.Tensor) -> torch.Tensor:
    """Interleave samples and their nearest maps: [s0, n0, s1, n1, ...]."""
    return torch.stack([samples, nearest], dim=1).reshape(-1, *samples.shape[1:])


def loss_curve_plot(log: Path, path: Path, family: str) -> None:
    """Training loss (eps MSE and MSE + vb), logged every few steps, with a running mean over 20 logs."""
    import json

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [json.loads(line) for line in log.read_text().splitlines()]
    steps = np.array([r["step"] for r in rows])
    fig, ax = plt.subplots(figsize=(6, 3.2))
    for key in ("mse", "loss"):
        values = np.array([r[key] for r in rows])
        smooth = np.convolve(values, np.ones(20) / 20, mode="valid")
        ax.plot(steps[19:], smooth, label=f"{key} (running mean of 20 logs)")
    ax.set_yscale("log")
    ax.set_xlabel("optimiser step")
    ax.set_title(f"{family} prior: training loss")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def evaluate_family(family: str, data: Path, count: int, steps: int, timing_steps: list[int]) -> list[tuple]:
    """Rows (family, quantity, value) of the table for one default model."""
    prior = load_prior(DEFAULT_MODELS[family])
    train = read_dataset(data, prior.height, family, prior.encoding).images
    enc = prior.encoding
    held = held_out_maps(family, count, prior.height, enc)
    start = time.perf_counter()
    rolled = draw_samples(prior, count, steps, seed=1, random_roll=True)
    seconds = (time.perf_counter() - start) / count
    plain = draw_samples(prior, count, steps, seed=1, random_roll=False)
    train_subset = train[torch.randperm(len(train), generator=torch.Generator().manual_seed(0))[:count]]
    f_held = features(held)
    rows = [
        (family, f"FSD samples ({steps} steps, roll) vs held-out", frechet_distance(features(rolled), f_held)),
        (family, f"FSD samples ({steps} steps, no roll) vs held-out", frechet_distance(features(plain), f_held)),
        (family, "FSD training maps vs held-out (floor)", frechet_distance(features(train_subset), f_held)),
        (family, "FSD blurred noise vs held-out (baseline)", frechet_distance(features(blurred_noise(count, prior.height, 0)), f_held)),
        (family, "seam ratio, samples with random roll", seam_ratio(rolled)),
        (family, "seam ratio, samples without roll", seam_ratio(plain)),
        (family, "seam ratio, held-out maps", seam_ratio(held)),
        (family, "brightest 0.5 % energy share, samples (median)", float(np.median(top_energy_shares(rolled, enc)))),
        (family, "brightest 0.5 % energy share, held-out (median)", float(np.median(top_energy_shares(held, enc)))),
        (family, "max / median luminance, samples (median)", float(luminance_over_median(rolled, enc).flatten(1)
                                                                     .max(1).values.median())),
        (family, "max / median luminance, held-out (median)", float(luminance_over_median(held, enc).flatten(1)
                                                                      .max(1).values.median())),
        (family, f"seconds per map, {steps} steps (batch 16)", seconds),
    ]
    for n in timing_steps:
        start = time.perf_counter()
        draw_samples(prior, 4, n, seed=2)
        rows.append((family, f"seconds per map, {n} steps (batch 4)", (time.perf_counter() - start) / 4))
    shown = rolled[:16]
    pairs = pair_grid(shown, nearest_training_maps(shown, train))
    write_grid(MODELS_DIR / f"{family}_samples.png", radiance_display(pairs, enc), columns=4)
    dynamic_range_plot(MODELS_DIR / f"{family}_dynamic_range.png", family, rolled, held, enc)
    log = MODELS_DIR / "logs" / f"{DEFAULT_MODELS[family].stem}.log.jsonl"
    if log.exists():
        loss_curve_plot(log, MODELS_DIR / f"{family}_loss.png", family)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--families", nargs="+", default=["outdoor", "indoor"])
    parser.add_argument("--data", default="results/prior_data/{family}_log_32.npz",
                        help="training data of a family: a packed .npz or a folder ({family} is replaced)")
    parser.add_argument("--count", type=int, default=96, help="samples and held-out maps per family")
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--timing-steps", type=int, nargs="*", default=[25, 100, 250])
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    backend.mitsuba(threads=args.threads)
    torch.manual_seed(0)
    rows = []
    for family in args.families:
        rows += evaluate_family(family, Path(args.data.format(family=family)), args.count, args.steps,
                                args.timing_steps)
    width = max(len(r[1]) for r in rows)
    print(f"| family  | {'quantity':<{width}} | value    |")
    print(f"|---------|{'-' * (width + 2)}|----------|")
    for family, name, value in rows:
        print(f"| {family:<7} | {name:<{width}} | {value:8.4g} |")


if __name__ == "__main__":
    main()
