"""Time the parts of one dps step on the demo and count Dr.Jit kernel compilations per step.

At the default setting (64 x 64 images, 16 spp, env 16 x 32, textures 64, 1 view per step, the
outdoor prior) it runs the body of `dpi.solve.dps.dps_sample`'s reverse loop, split in parts:
  network forward   eps_theta on the randomly rolled x_t (with the autograd graph, as dps builds it)
  render fwd+bwd    ||y - R(L, k, c)|| of one view and its backward pass to L and the textures
  network backward  the gradient dL/dx_t back through prior_to_env, x0_hat and the UNet
  update            p_mean_variance, prior_to_env, the guided reverse step and Adam on the materials
Dr.Jit's kernel history (JitFlag.KernelHistory) says, per step, how many kernels were launched and
whether each came from the in-memory cache, the on-disk cache (~/.drjit) or was compiled fresh.
Then the same step with the Mitsuba scene rebuilt every step (a new Renderer, as a naive loop
would do) against the scene built once and updated in place, as dps uses it. Warm-up steps (and
one render of every training view) are not timed.

With 2 threads on a machine whose cores are busy with other work, torch's OpenMP threads spin-wait
(libgomp's default) and the network can run tens of times slower; compare with
OMP_WAIT_POLICY=PASSIVE in the environment (the header line says which was set).

    .venv/bin/python benchmarks/dps_step.py [--steps 20] [--rebuilt-steps 6] [--threads 2]
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import dataclass, fields

import numpy as np
import torch
from tradeoff import ROOT, Setting, capture_at

from dpi import backend
from dpi.capture import load_capture
from dpi.materials import MaterialTextures
from dpi.prior.diffusion import Diffusion, model_output_with_random_roll, model_timesteps, p_mean_variance
from dpi.prior.sample import Prior, load_scene_prior
from dpi.render import Renderer, RenderSettings
from dpi.solve.dps import (DPSConfig, estimate_radiance_scale, material_optimizer, prior_to_env, rho_schedule,
                           scale_to_bound)
from dpi.solve.init import starting_materials
from dpi.solve.problem import InverseProblem, ProblemSettings


@dataclass
class StepCost:
    """Milliseconds of the parts of one dps step and the Dr.Jit kernels it launched."""

    build: float
    network_forward: float
    render: float
    network_backward: float
    update: float
    total: float
    kernels: int
    memory_hits: int
    disk_hits: int
    compiled: int
    compile_ms: float


@dataclass
class Loop:
    """The state the reverse loop carries from step to step (x_t, materials, Adam, random stream)."""

    problem: InverseProblem
    prior: Prior
    diffusion: Diffusion
    cfg: DPSConfig
    scale: float
    x: torch.Tensor
    materials: MaterialTextures
    optimizer: torch.optim.Optimizer
    generator: torch.Generator
    rho: np.ndarray
    seed: int


def kernel_counts() -> dict[str, float]:
    """Kernels launched since the last call: total, in-memory hits, disk hits, fresh compiles, compile ms."""
    import drjit as dr

    history = dr.kernel_history([dr.KernelType.JIT])
    memory = sum(bool(k["cache_hit"]) and not k["cache_disk"] for k in history)
    disk = sum(bool(k["cache_disk"]) for k in history)  # a disk load also sets cache_hit
    return {"kernels": len(history), "memory_hits": memory, "disk_hits": disk,
            "compiled": len(history) - memory - disk,
            "compile_ms": sum(k["backend_time"] for k in history if not k["cache_hit"])}  # set for fresh ones only


def make_loop(threads: int, seed: int) -> Loop:
    """The demo's problem at the default setting, the init materials, the prior and a fresh x_T."""
    base = Setting()
    capture = load_capture(capture_at(base.resolution, threads))
    problem = InverseProblem(capture, ProblemSettings(env_height=base.env_height, texture_size=base.texture_size),
                             RenderSettings(spp=base.spp, threads=threads))
    init = problem.load_decomposition(ROOT / "results" / "demo" / "init")
    prior = load_scene_prior(capture.options)
    cfg = DPSConfig(steps=base.steps, views_per_step=base.views_per_step)
    generator = torch.Generator().manual_seed(seed)
    materials = starting_materials(init)
    for _, t in materials.items():
        t.requires_grad_(True)
    optimizer = material_optimizer(materials, cfg)
    diffusion = prior.schedule(cfg.steps)
    x = torch.randn((1, 3, prior.height, 2 * prior.height), generator=generator)
    return Loop(problem, prior, diffusion, cfg, estimate_radiance_scale(init.env, prior), x, materials, optimizer,
                generator, rho_schedule(cfg, diffusion.num_timesteps), seed)


def rebuild_renderer(problem: InverseProblem) -> None:
    """Replace the problem's renderer by a new one: a new Mitsuba scene (the naive per-step loop)."""
    old = problem.renderer
    problem.renderer = Renderer(problem.capture.mesh, old.cameras, old.env_height, old.texture_size, old.settings)


def dps_step(loop: Loop, n: int, rebuild: bool) -> StepCost:
    """One reverse step n of dps (as dps_sample, gradients split at the env map), timed part by part."""
    kernel_counts()
    ms = dict.fromkeys(("build", "network_forward", "render", "network_backward", "update"), 0.0)
    start = clock = time.perf_counter()

    def lap(name: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        ms[name] += 1e3 * (now - clock)
        clock = now

    if rebuild:
        rebuild_renderer(loop.problem)
    lap("build")
    i = loop.diffusion.num_timesteps - 1 - n
    x = loop.x.detach().requires_grad_(True)
    t = torch.full((1,), i, dtype=torch.long)
    output = model_output_with_random_roll(loop.prior.model, x, model_timesteps(loop.diffusion, t), loop.generator)
    lap("network_forward")
    p = p_mean_variance(loop.diffusion, output, x, t)
    env = prior_to_env(p["x0"].clamp(-1, 1), loop.prior, loop.scale, loop.problem.settings.env_height)
    views = loop.problem.sample_views(loop.cfg.views_per_step, loop.generator)
    lap("update")
    env_leaf = env.detach().requires_grad_(True)
    loop.optimizer.zero_grad()
    loss = loop.problem.residual_norm(env_leaf, loop.materials, views, seed=loop.seed * 7919 + n)
    loss.backward()
    lap("render")
    env.backward(env_leaf.grad)
    lap("network_backward")
    with torch.no_grad():
        noise = torch.randn(x.shape, generator=loop.generator) if i > 0 else torch.zeros_like(x)
        x_next = p["mean"] + torch.exp(0.5 * p["log_variance"]) * noise
        if torch.isfinite(x.grad).all():
            x_next = x_next - loop.rho[n] * scale_to_bound(x.grad, loop.cfg.guidance_bound)
            loop.optimizer.step()
            loop.materials.clamp_()
    loop.x = x_next
    lap("update")
    ms["total"] = 1e3 * (time.perf_counter() - start)
    return StepCost(**ms, **kernel_counts())


def warm_up(loop: Loop, steps: int) -> dict[str, float]:
    """Render every training view once (forward + backward), then run `steps` steps; their kernel counts."""
    kernel_counts()
    env = prior_to_env(loop.x.clamp(-1, 1), loop.prior, loop.scale, loop.problem.settings.env_height)
    env = env.detach().requires_grad_(True)
    for v in loop.problem.train_ids:
        loop.problem.residual_norm(env, loop.materials, [v], seed=v).backward()
    loop.optimizer.zero_grad()
    counts = kernel_counts()
    for n in range(steps):
        cost = dps_step(loop, n, rebuild=False)
        counts = {k: v + getattr(cost, k) for k, v in counts.items()}
    return counts


def stats(costs: list[StepCost], name: str) -> tuple[float, float]:
    """Median and 90th percentile of one field over the steps."""
    values = [getattr(c, name) for c in costs]
    return float(np.median(values)), float(np.percentile(values, 90))


def setting_line(setting: Setting) -> str:
    """The knobs that matter for one step, on one line."""
    return (f"{setting.resolution}x{setting.resolution} images, {setting.spp} spp, env {setting.env_height}x"
            f"{2 * setting.env_height}, textures {setting.texture_size}, {setting.views_per_step} view/step")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=20, help="timed steps with the scene reused")
    parser.add_argument("--rebuilt-steps", type=int, default=6, help="timed steps with the scene rebuilt each step")
    parser.add_argument("--warmup", type=int, default=3, help="untimed steps first")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    backend.mitsuba("auto", args.threads)
    import drjit as dr

    dr.set_flag(dr.JitFlag.KernelHistory, True)
    loop = make_loop(args.threads, args.seed)
    first = kernel_counts()
    warm = warm_up(loop, args.warmup)
    reused = [dps_step(loop, args.warmup + n, rebuild=False) for n in range(args.steps)]
    offset = args.warmup + args.steps
    rebuilt = [dps_step(loop, offset + n, rebuild=True) for n in range(args.rebuilt_steps)]

    policy = os.environ.get("OMP_WAIT_POLICY", "unset")
    print(f"dps step on the demo: {setting_line(Setting())}, {args.threads} threads, "
          f"Mitsuba {loop.problem.renderer.mi.variant()}, OMP_WAIT_POLICY={policy}")
    print(f"set-up (scene build, first kernels): {first['kernels']} kernels, {first['compiled']} compiled; "
          f"warm-up ({len(loop.problem.train_ids)} views + {args.warmup} steps): {warm['kernels']} kernels, "
          f"{warm['compiled']} compiled, {warm['disk_hits']} from disk")
    print(f"\nscene reused, {args.steps} steps:")
    print(f"{'part':<34} {'median ms':>10} {'p90 ms':>9}")
    parts = {"network forward (UNet, random roll)": "network_forward",
             "network backward (UNet to x_t)": "network_backward",
             "render forward + backward (1 view)": "render",
             "Adam, reverse step and the rest": "update", "whole step": "total"}
    for label, name in parts.items():
        median, p90 = stats(reused, name)
        print(f"{label:<34} {median:>10.1f} {p90:>9.1f}")
    print(f"\n{'scene':<8} {'steps':>5} {'ms/step':>8} {'p90':>7} {'mean':>7} {'build ms':>9} {'render ms':>10} "
          f"{'kernels':>8} {'compiled':>9} {'mem hits':>9} {'disk hits':>10} {'compile ms':>11}  (medians; counts: means)")
    for label, costs in (("reused", reused), ("rebuilt", rebuilt)):
        if not costs:
            continue
        mean = {f.name: float(np.mean([getattr(c, f.name) for c in costs])) for f in fields(StepCost)}
        median, p90 = stats(costs, "total")
        print(f"{label:<8} {len(costs):>5} {median:>8.1f} {p90:>7.1f} {mean['total']:>7.1f} "
              f"{stats(costs, 'build')[0]:>9.1f} {stats(costs, 'render')[0]:>10.1f} {mean['kernels']:>8.1f} "
              f"{mean['compiled']:>9.1f} {mean['memory_hits']:>9.1f} {mean['disk_hits']:>10.1f} "
              f"{mean['compile_ms']:>11.1f}")
    for label, costs in (("reused", reused), ("rebuilt", rebuilt)):
        print(f"{label}: compiled/disk-loaded kernels per step {[(c.compiled, c.disk_hits) for c in costs]}")


if __name__ == "__main__":
    main()
