"""Time the parts of one dps step and of a whole sample on the demo, and count Dr.Jit kernel compilations.

At the default preset (64 x 64 images, 16 spp, its env map and textures, the demo's prior) it runs
`dpi.solve.dps.posterior_steps` (the loop `dps_sample` runs, not a copy of it) for each sampler and
reads each step's timings from its record:
  network            eps_theta on the randomly rolled x_t (paper: with the autograd graph)
  transport          proximal: recording the light transport (the first step only; not in the table)
  solve              proximal: the map's Gauss-Newton solve on the recorded transport
  data               proximal: the data updates on the recorded transport
  render             paper: the data term's render, forward and backward
  network_backward   paper: the gradient back through x0_hat and the UNet to x_t
  rest               the reverse step, Adam and bookkeeping
Dr.Jit's kernel history (JitFlag.KernelHistory) says, per step, how many kernels were launched and
whether each came from the in-memory cache, the on-disk cache (~/.drjit) or was compiled fresh.
Then the same steps with the Mitsuba scene rebuilt before every step (a new Renderer, as a naive
loop would do) against the scene built once and updated in place, as dps uses it. Warm-up steps
(and one render of every training view) are not timed. Then the data term over all training views
with its gradient w.r.t. the map and the albedo: path traced against the recorded light transport,
and the cost of one recording. Last, whole samples side by side: each sampler's sample and a `none`
sample at the default preset, with the sample's time split into its parts.

With 2 threads on a machine whose cores are busy with other work, torch's OpenMP threads spin-wait
(libgomp's default) and the network can run tens of times slower; compare with
OMP_WAIT_POLICY=PASSIVE in the environment (the header line says which was set).

    .venv/bin/python benchmarks/timing/dps_step.py [--samplers proximal paper] [--steps 20] [--rebuilt-steps 6] [--threads 2]
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import replace
from typing import Any, Iterator

import numpy as np
import torch

from dpi.capture import load_capture
from dpi.io.layout import INIT
from dpi.prior.sample import load_scene_prior
from dpi.render import backend
from dpi.render.renderer import RenderConfig, Renderer
from dpi.solve.decomposition import Decomposition
from dpi.solve.dps import SAMPLERS, DPSConfig, dps_sample, posterior_steps, start_run
from dpi.solve.dps.state import DPSRun
from dpi.solve.materials import MaterialTextures
from dpi.solve.problem import InverseProblem, ProblemConfig
from dpi.studies.demo_costs import DEMO, capture_at, demo_pipeline, preset_setting

PIPELINE = demo_pipeline()

PARTS = {"network": "network forward (UNet, random roll)",
         "solve": "Gauss-Newton solve of the map on the transport (proximal)",
         "data": "data updates on the transport (proximal)",
         "render": "render forward + backward (paper)",
         "network_backward": "network backward (paper)", "rest": "reverse step, Adam and the rest",
         "total": "whole step"}
TIMED = ("network", "transport", "solve", "data", "render", "network_backward")
"""the parts a step's record times (seconds_<part>); the transport's recording (first step) is not a step's cost"""


def kernel_counts() -> dict[str, float]:
    """Kernels launched since the last call: total, in-memory hits, disk hits, fresh compiles, compile ms."""
    import drjit as dr

    history = dr.kernel_history([dr.KernelType.JIT])
    memory = sum(bool(k["cache_hit"]) and not k["cache_disk"] for k in history)
    disk = sum(bool(k["cache_disk"]) for k in history)  # a disk load also sets cache_hit
    return {"kernels": len(history), "memory_hits": memory, "disk_hits": disk,
            "compiled": len(history) - memory - disk,
            "compile_ms": sum(k["backend_time"] for k in history if not k["cache_hit"])}  # set for fresh ones only


def make_run(sampler: str, threads: int, seed: int) -> tuple[DPSRun, Iterator[dict[str, Any]]]:
    """The demo's problem at the default setting, the init, the prior, and the sampler's step loop."""
    base = preset_setting()
    capture = load_capture(capture_at(base.resolution, threads, PIPELINE.layout.results / "benchmarks"))
    problem = InverseProblem(capture, ProblemConfig(env_height=base.env_height, texture_size=base.texture_size),
                             RenderConfig(spp=base.spp, threads=threads))
    init = problem.load_decomposition(PIPELINE.layout.scene(DEMO).sample_dir(INIT))
    cfg = DPSConfig.from_dict({"sampler": sampler, "steps": base.steps})
    run, state = start_run(problem, load_scene_prior(capture.options, PIPELINE.prior_checkpoint(DEMO)), init, cfg, seed)
    return run, posterior_steps(run, state)


def rebuild_renderer(problem: InverseProblem) -> None:
    """Replace the problem's renderer by a new one: a new Mitsuba scene (the naive per-step loop)."""
    old = problem.renderer
    problem.renderer = Renderer(problem.capture.mesh, old.cameras, old.env_height, old.texture_size, old.settings)


def timed_steps(run: DPSRun, steps: Iterator[dict[str, Any]], count: int, rebuild: bool) -> list[dict[str, float]]:
    """The next `count` steps' part times (ms) and kernel counts, optionally rebuilding the scene first."""
    costs = []
    for _ in range(count):
        kernel_counts()
        if rebuild:
            rebuild_renderer(run.problem)
        record = next(steps)
        parts = {part: 1e3 * record.get(f"seconds_{part}", 0.0) for part in TIMED}
        total = 1e3 * record["seconds"] - parts.pop("transport")
        costs.append({**parts, "rest": total - sum(parts.values()), "total": total, **kernel_counts()})
    return costs


def warm_up(run: DPSRun, steps: Iterator[dict[str, Any]], count: int) -> dict[str, float]:
    """Render every training view once (Dr.Jit compiles or loads its kernels), then run `count` steps."""
    kernel_counts()
    h = run.problem.settings.env_height
    grey = MaterialTextures.constant(run.problem.settings.texture_size)
    for v in run.problem.train_ids:
        run.problem.render(torch.ones(h, 2 * h, 3), grey, v, seed=v)
    counts = kernel_counts()
    for cost in timed_steps(run, steps, count, rebuild=False):
        counts = {k: counts[k] + cost[k] for k in counts}
    return counts


def data_term_costs(problem: InverseProblem, init: Decomposition, repeats: int) -> None:
    """Print the data term over all training views, evaluated with its gradient w.r.t. the map and the albedo:
    path traced against the recorded light transport (dpi.solve.transport; a map finer than it area-sampled to
its rows), and what one recording costs."""
    from dpi.io.images import resize
    from dpi.solve.transport import record_transport

    materials, views = init.materials, problem.train_ids
    settings = DPSConfig().proximal.transport
    start = time.perf_counter()
    transport = record_transport(problem, materials, init.env, settings, seed=1)
    recording = time.perf_counter() - start
    costs = {}
    for name, loss in (("render", lambda env, albedo: problem.data_loss(env, replace(materials, albedo=albedo), views,
                                                                         seed=3)),
                       ("transport", lambda env, albedo: transport.sum_squares(
                           resize(env, transport.height, 2 * transport.height), albedo))):
        loss(init.env.clone().requires_grad_(True), materials.albedo.clone().requires_grad_(True)).backward()  # warm
        start = time.perf_counter()
        for _ in range(repeats):
            loss(init.env.clone().requires_grad_(True), materials.albedo.clone().requires_grad_(True)).backward()
        costs[name] = 1e3 * (time.perf_counter() - start) / repeats
    print(f"\ndata term over all {len(views)} training views, loss and gradient w.r.t. map and albedo "
          f"({repeats} repeats):")
    print(f"  path traced ({problem.renderer.settings.spp} spp): {costs['render']:.1f} ms")
    print(f"  recorded transport ({transport.pixels} of {transport.foreground} foreground pixels): "
          f"{costs['transport']:.2f} ms "
          f"({costs['render'] / costs['transport']:.0f}x faster); one recording ({settings.spp} paths + "
          f"{settings.direct_spp} direct samples per pixel) {1e3 * recording:.0f} ms "
          f"(= {recording / (1e-3 * costs['render']):.1f} path-traced evaluations), {transport.nbytes / 2**20:.0f} MB")


def sample_split(samplers: list[str], threads: int, seed: int) -> None:
    """Whole samples at the default preset, one after the other: each sampler's and a `none` sample; seconds per
    part (the transport's recording, the network, the data steps, the refinement) and in all."""
    from dpi.solve.classic import classic_sample

    run, _ = make_run(samplers[0], threads, seed)
    problem, init, prior = run.problem, run.init, run.prior
    print(f"\nwhole samples side by side ({threads} threads; seconds):")
    print(f"{'method':<14} {'total':>7} {'transport':>10} {'network':>8} {'data':>7} {'refine':>7}")
    for sampler in samplers:
        cfg = PIPELINE.method_settings("dps")
        cfg.sampler = sampler
        start = time.perf_counter()
        trace = dps_sample(problem, prior, init, cfg, seed, progress=False).decomposition.trace
        total = time.perf_counter() - start
        parts = {k: sum(s.get(f"seconds_{k}", 0.0) for s in trace.steps) for k in TIMED}
        data = sum(v for k, v in parts.items() if k not in ("network", "transport"))
        print(f"{'dps ' + sampler:<14} {total:>7.1f} {parts['transport']:>10.1f} {parts['network']:>8.1f} "
              f"{data:>7.1f} {trace.info['refine']['seconds']:>7.1f}")
    start = time.perf_counter()
    classic_sample(problem, "none", init, PIPELINE.method_settings("none"), seed, progress=False)
    print(f"{'none':<14} {time.perf_counter() - start:>7.1f}")


def stats(costs: list[dict[str, float]], name: str) -> tuple[float, float]:
    """Median and 90th percentile of one field over the steps."""
    values = [c[name] for c in costs]
    return float(np.median(values)), float(np.percentile(values, 90))


def report(sampler: str, reused: list[dict[str, float]], rebuilt: list[dict[str, float]]) -> None:
    """Print one sampler's tables: parts of a step, then scene reused against rebuilt."""
    print(f"\n{sampler}: scene reused, {len(reused)} steps")
    print(f"{'part':<36} {'median ms':>10} {'p90 ms':>9}")
    for name, label in PARTS.items():
        median, p90 = stats(reused, name)
        print(f"{label:<36} {median:>10.1f} {p90:>9.1f}")
    print(f"{'scene':<8} {'steps':>5} {'ms/step':>8} {'p90':>7} {'render ms':>10} {'kernels':>8} {'compiled':>9} "
          f"{'mem hits':>9} {'disk hits':>10} {'compile ms':>11}  (medians; counts: means)")
    for label, costs in (("reused", reused), ("rebuilt", rebuilt)):
        if not costs:
            continue
        mean = {k: float(np.mean([c[k] for c in costs])) for k in costs[0]}
        median, p90 = stats(costs, "total")
        print(f"{label:<8} {len(costs):>5} {median:>8.1f} {p90:>7.1f} {stats(costs, 'render')[0]:>10.1f} "
              f"{mean['kernels']:>8.1f} {mean['compiled']:>9.1f} {mean['memory_hits']:>9.1f} "
              f"{mean['disk_hits']:>10.1f} {mean['compile_ms']:>11.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samplers", nargs="*", default=list(SAMPLERS), choices=list(SAMPLERS))
    parser.add_argument("--steps", type=int, default=20, help="timed steps with the scene reused")
    parser.add_argument("--rebuilt-steps", type=int, default=6, help="timed steps with the scene rebuilt each step")
    parser.add_argument("--warmup", type=int, default=3, help="untimed steps first")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeats", type=int, default=10, help="evaluations timed per data term")
    args = parser.parse_args()

    backend.mitsuba("auto", args.threads)
    import drjit as dr

    dr.set_flag(dr.JitFlag.KernelHistory, True)
    policy = os.environ.get("OMP_WAIT_POLICY", "unset")
    base = preset_setting()
    print(f"dps step on the demo: {base.resolution}x{base.resolution} images, {base.spp} spp, env {base.env_height}x"
          f"{2 * base.env_height}, textures {base.texture_size}, {args.threads} threads, OMP_WAIT_POLICY={policy}")
    for sampler in args.samplers:
        run, steps = make_run(sampler, args.threads, args.seed)
        first = kernel_counts()
        warm = warm_up(run, steps, args.warmup)
        reused = timed_steps(run, steps, args.steps, rebuild=False)
        rebuilt = timed_steps(run, steps, args.rebuilt_steps, rebuild=True)
        print(f"\n{sampler}: set-up {first['kernels']} kernels ({first['compiled']} compiled); warm-up "
              f"({len(run.problem.train_ids)} views + {args.warmup} steps) {warm['kernels']} kernels, "
              f"{warm['compiled']} compiled, {warm['disk_hits']} from disk")
        report(sampler, reused, rebuilt)
    data_term_costs(run.problem, run.init, args.repeats)
    sample_split([s for s in args.samplers if s != "paper"] or args.samplers, args.threads, args.seed)


if __name__ == "__main__":
    main()
