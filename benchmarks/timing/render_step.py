"""Time one differentiable render step (forward + backward) and one init iteration vs image size and spp.

Uses the demo scene's mesh, ground-truth sky and textures (captures/demo, rendered first if missing).
Prints a table; the first, kernel-compiling call of every configuration is excluded.

    .venv/bin/python benchmarks/timing/render_step.py [--sizes 32 64 128] [--spp 4 16 64] [--threads 2]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch

from dpi.capture.cameras import from_fov, orbit
from dpi.io.exr import read_exr
from dpi.render.renderer import RenderConfig, Renderer
from dpi.solve.materials import MaterialTextures
from dpi.synth.capture import SynthConfig, make_synthetic_capture

DEMO = Path(__file__).resolve().parents[2] / "captures" / "demo"


def time_render_step(renderer: Renderer, env: torch.Tensor, mats: MaterialTextures, repeats: int) -> float:
    """Median seconds of forward + backward of one view (after one warm-up call)."""
    env = env.clone().requires_grad_(True)
    albedo = mats.albedo.clone().requires_grad_(True)
    times = []
    for i in range(repeats + 1):
        start = time.perf_counter()
        image = renderer.render(env, albedo, mats.roughness, mats.metallic, view=i % len(renderer.cameras), seed=i)
        image.square().mean().backward()
        times.append(time.perf_counter() - start)
    return float(np.median(times[1:]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[32, 64, 128])
    parser.add_argument("--spp", type=int, nargs="+", default=[4, 16, 64])
    parser.add_argument("--views-per-step", type=int, default=4,
                        help="views per init iteration; an iteration is estimated as views x step (Adam is negligible)")
    parser.add_argument("--env-height", type=int, default=16)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()

    if not (DEMO / ".synth.json").exists():
        make_synthetic_capture(DEMO, SynthConfig(), threads=args.threads)
    env = torch.from_numpy(read_exr(DEMO / "gt" / "envmap.exr"))
    env = torch.nn.functional.interpolate(env.permute(2, 0, 1)[None], size=(args.env_height, 2 * args.env_height),
                                          mode="area")[0].permute(1, 2, 0).contiguous()
    mats = MaterialTextures.load(DEMO / "gt", 64)
    print(f"demo mesh, env {args.env_height}x{2 * args.env_height}, textures 64^2, prb max_depth 5, "
          f"{args.threads} threads, {args.views_per_step} views per init iteration")
    print(f"{'image':>9} {'spp':>5} {'render fwd+bwd [s]':>19} {'init iter est. [s]':>19} {'Mrays/s':>8}")
    for size in args.sizes:
        cams = [from_fov(p, size, size, 35.0) for p in orbit(args.views_per_step, 4.0, (10.0, 35.0))]
        for spp in args.spp:
            renderer = Renderer(DEMO / "mesh.ply", cams, args.env_height, 64,
                                RenderConfig(spp=spp, threads=args.threads))
            step = time_render_step(renderer, env, mats, args.repeats)
            rays = size * size * spp / step / 1e6
            print(f"{size:>4}x{size:<4} {spp:>5} {step:>19.3f} {step * args.views_per_step:>19.3f} {rays:>8.2f}")


if __name__ == "__main__":
    main()
