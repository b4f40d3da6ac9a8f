"""Speed and dynamic range of the procedural outdoor generator, per scene kind.

    .venv/bin/python benchmarks/timing/outdoor_generator.py [--height 32] [--count 50] [--sheet outdoor_examples.png]

For each kind (urban, landscape, overcast) it generates `count` maps on one thread and prints the
CPU seconds per map (process time, so other jobs on the machine do not inflate it), the median and
max of max/median luminance, and the median share of the energy (luminance times texel solid
angle) carried by the brightest 0.5 % of texels. With --sheet it also writes a contact sheet:
8 maps per kind, one kind per two rows, each median-normalised, Reinhard tone-mapped, sRGB
encoded and enlarged 4x.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from dpi.evaluation.metrics import tonemap
from dpi.io.images import luminance, write_srgb
from dpi.light.envmap import texel_solid_angles
from dpi.render import backend
from dpi.worlds.outdoor import SCENE_KINDS, outdoor_envmap

TOP_FRACTION = 0.005
SHEET_COLUMNS = 4
SHEET_SCALE = 4
SHEET_MEDIAN = 0.5  # luminance the median texel is shown at before tone mapping


def top_energy_share(env: np.ndarray) -> float:
    """Share of a map's energy (luminance x solid angle) in its brightest TOP_FRACTION of texels by radiance."""
    lum = luminance(env.astype(np.float64))
    energy = (lum * texel_solid_angles(env.shape[0])).ravel()
    count = max(1, int(round(TOP_FRACTION * lum.size)))
    return float(energy[np.argsort(lum.ravel())[-count:]].sum() / energy.sum())


def display(env: np.ndarray) -> np.ndarray:
    """A map median-normalised, Reinhard tone-mapped and enlarged, with a 2-texel white border, linear for write_srgb."""
    shown = tonemap(env * SHEET_MEDIAN / np.median(luminance(env)))
    big = np.repeat(np.repeat(shown, SHEET_SCALE, 0), SHEET_SCALE, 1)
    return np.pad(big, ((2, 2), (2, 2), (0, 0)), constant_values=1.0)


def contact_sheet(maps: list[np.ndarray]) -> np.ndarray:
    """Tiles of `maps` in rows of SHEET_COLUMNS."""
    tiles = [display(env) for env in maps]
    rows = [np.concatenate(tiles[i:i + SHEET_COLUMNS], axis=1) for i in range(0, len(tiles), SHEET_COLUMNS)]
    return np.concatenate(rows, axis=0)


def main() -> None:
    """Print the per-kind table and optionally write the contact sheet."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--height", type=int, default=32)
    parser.add_argument("--count", type=int, default=50)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--sheet", help="write a contact sheet PNG of 8 maps per kind here")
    args = parser.parse_args()
    backend.mitsuba(threads=1)  # the training set is generated on one core
    outdoor_envmap(args.height, np.random.default_rng(args.seed))  # warms up Mitsuba before timing
    print(f"{'kind':10s} {'s/map':>7s} {'DR median':>10s} {'DR max':>10s} {'top0.5% share':>14s}")
    sheet = []
    for k, kind in enumerate(SCENE_KINDS):
        rng = np.random.default_rng([args.seed, k])
        start = time.process_time()
        maps = [outdoor_envmap(args.height, rng, kind) for _ in range(args.count)]
        seconds = (time.process_time() - start) / args.count
        ranges = [luminance(env).max() / np.median(luminance(env)) for env in maps]
        shares = [top_energy_share(env) for env in maps]
        print(f"{kind:10s} {seconds:7.3f} {np.median(ranges):10.1f} {np.max(ranges):10.1f} {np.median(shares):14.3f}")
        sheet += maps[:8]
    if args.sheet:
        write_srgb(args.sheet, contact_sheet(sheet))


if __name__ == "__main__":
    main()
