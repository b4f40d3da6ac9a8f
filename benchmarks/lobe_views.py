"""Which lobe width the training views favour, judged under which albedo (issue 77).

    .venv/bin/python benchmarks/lobe_views.py --work DIR [DIR ...] [--scenes ...] [--out CSV]

For each rough scene of the study folders with true textures, the training views' transport is recorded as a dps
sample with `proximal.lobe_choice` records it: under the sample's start, at the init's lobe width and at
dpi.solve.dps.lobe_choice.LOBE_FACTORS times it. Each level is judged as that choice judges it (the share of the
views' energy a free non-negative map leaves, `lobe_choice.unexplained`), under one albedo:
- `start`: the samples' grey start (what the sampler uses);
- `init`: the init's albedo, fixed;
- `blocks`: the init's albedo times a free factor per block of BLOCK x BLOCK texels and channel, solved with the map
  (alternating): the broad level free, the pattern the init's, each unknown seen by many pixels and views;
- `truth`: the true albedo, fixed (what a perfect albedo would say).
A row per scene and albedo: the factor favoured, the true one (the truth's median alpha over the init's), and the
share at each factor. The CSV is rewritten whole.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from dpi.config.pipeline import Pipeline
from dpi.evaluation.truth import true_materials
from dpi.io.layout import INIT
from dpi.solve.dps.balance_trade import normal_texture
from dpi.solve.dps.data_term import start_transport
from dpi.solve.dps.lobe_choice import LOBE_FACTORS, nonnegative_quadratic, unexplained
from dpi.solve.init import is_glossy
from dpi.solve.transport import LightTransport
from dpi.stages.inverse import load_problem
from dpi.studies.engine import results_csv, workflow_config, write_rows
from dpi.studies.scenes import STUDY_SCENES, drawn_scenes

FACTORS = (1.0, *LOBE_FACTORS)
"""each recorded level's lobe width over the init's"""
BLOCK = 8
"""texels per side of one free albedo factor (`blocks`)"""
ROUNDS = 6
"""alternations of map and block factors"""
SEED = 97


def block_index(size: int) -> np.ndarray:
    """(size * size,) the BLOCK x BLOCK block of each texel, row-major."""
    texel = np.arange(size * size)
    return (texel // size) // BLOCK * (-(-size // BLOCK)) + (texel % size) // BLOCK


def block_operator(transport: LightTransport, albedo: torch.Tensor) -> np.ndarray:
    """(P, blocks, 3): the albedo each recorded pixel sees per unit factor of each block (the texture's own
    pattern inside it)."""
    lookup, blocks = transport.lookup, block_index(albedo.shape[0])
    texels = lookup.texels.numpy()
    out = np.zeros((lookup.shape[0], int(blocks.max()) + 1, 3))
    np.add.at(out, (lookup.rows.numpy(), blocks[texels]),
              lookup.weights.double().numpy()[:, None] * albedo.reshape(-1, 3).double().numpy()[texels])
    return out


def blocks_unexplained(transport: LightTransport, albedo: torch.Tensor, level: int) -> float:
    """`unexplained` with the block factors of the albedo and the map solved together (alternating from 1; a block
    no pixel sees keeps factor 0, which nothing reads)."""
    operator = block_operator(transport, albedo)
    factors = np.ones(operator.shape[1:])
    slope, offset = (transport.mean[k, level].double().numpy() for k in (0, 1))
    observed = transport.observed.double().numpy()
    for _ in range(ROUNDS):
        seen = np.einsum("pbc,bc->pc", operator, factors)
        for c in range(3):
            matrix = seen[:, c, None] * slope[c] + offset[c]
            light = nonnegative_quadratic(matrix.T @ matrix, matrix.T @ observed[:, c])
            design = operator[:, :, c] * (slope[c] @ light)[:, None]
            factors[:, c] = nonnegative_quadratic(design.T @ design, design.T @ (observed[:, c] - offset[c] @ light))
    scaled = albedo.reshape(-1, 3).double() * torch.from_numpy(factors[block_index(albedo.shape[0])])
    return unexplained(transport, scaled.reshape(albedo.shape).float(), level)


def scene_rows(scene: str, folder: Path, pipeline: Pipeline) -> list[dict]:
    """The rows of one scene (module notes)."""
    problem = load_problem(folder / "capture.json", pipeline.solve_settings(1))
    init = problem.load_decomposition(folder / INIT)
    if is_glossy(init.materials):
        return []
    cfg = pipeline.method_settings("dps")
    start = cfg.start_materials(init)
    size = init.materials.albedo.shape[0]
    truth = true_materials(problem, size)
    chart = torch.from_numpy(normal_texture(problem, size)[1])
    true_factor = float((truth.roughness[..., 0][chart].median() / init.materials.roughness[..., 0][chart].median())
                        ** 2)
    transport = start_transport(problem, init, start, cfg.proximal.transport, SEED, LOBE_FACTORS)
    albedo = init.materials.albedo.detach()
    judges = {"start": lambda level: unexplained(transport, start.albedo, level),
              "init": lambda level: unexplained(transport, albedo, level),
              "blocks": lambda level: blocks_unexplained(transport, albedo, level),
              "truth": lambda level: unexplained(transport, truth.albedo, level)}
    rows = []
    for name, judge in judges.items():
        shares = [judge(level) for level in range(len(FACTORS))]
        rows.append({"scene": scene, "group": STUDY_SCENES[scene][0], "albedo": name,
                     "favoured": round(FACTORS[int(np.argmin(shares))], 3), "true": round(true_factor, 3),
                     **{f"share_{f:.2f}": round(v, 5) for f, v in sorted(zip(FACTORS, shares))}})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--work", type=Path, nargs="+", required=True, help="study folders")
    parser.add_argument("--scenes", nargs="*", default=None, help="default: every rough scene with true textures")
    parser.add_argument("--out", type=Path, default=results_csv("lobe_views"))
    args = parser.parse_args()
    pipeline = Pipeline(workflow_config())
    rows = []
    for name, folder in drawn_scenes(args.work, args.scenes):
        if (folder / INIT).exists():
            new = scene_rows(name, folder, pipeline)
            rows += new
            for row in new:
                print(" ".join(f"{k} {v}" for k, v in row.items()), flush=True)
    write_rows(args.out, rows, settings="")


if __name__ == "__main__":
    main()
