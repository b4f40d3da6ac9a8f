"""The `paper` preset on a GPU (issue 32): the authors' guided-diffusion 256 network loads and runs, and the
preset's init, one dps sample and its evaluation are timed on the demo and on a posterior-study scene.

The network check builds `dpi.prior.unet.PAPER_CONFIG` with random weights, saves it as a raw
guided-diffusion state dict, loads it back through `load_checkpoint` and times a forward (and a
forward + backward) of one 128 x 256 map. The stages run through the workflow's own stage functions
(dpi.stages) with the preset's settings; Mitsuba's variant is the config's `auto` (cuda_ad_rgb on a GPU).
A smoke run on the CPU: `--presets draft --skip-network`.

    python benchmarks/timing/paper_preset_gpu.py [--scenes demo blob_sun] [--presets default paper] [--out OUT] [--work DIR]

Rows (part, scene, preset, variant, device, seconds, detail) go to OUT/paper_preset_gpu.csv as each part ends, so a
run cut short keeps what it measured; a table is printed last.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shutil
import statistics
import tempfile
import time
import traceback
from pathlib import Path
from typing import Any, Callable

import torch

from dpi.io.layout import INIT, Layout
from dpi.studies.engine import PROVENANCE, current_commit, job_settings, prepare_capture, settings_hash
from dpi.studies.scenes import POSTERIOR_SCENES as SCENES

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "captures" / "demo"
COLUMNS = ("part", "scene", "preset", "variant", "device", "seconds", "detail")


def timed(fn: Callable[[], Any], repeats: int, device: torch.device) -> float:
    """Median seconds of `fn` over `repeats` calls after one warm-up, synchronising a GPU around each."""
    times = []
    for _ in range(repeats + 1):
        if device.type == "cuda":
            torch.cuda.synchronize()
        start = time.perf_counter()
        fn()
        if device.type == "cuda":
            torch.cuda.synchronize()
        times.append(time.perf_counter() - start)
    return statistics.median(times[1:])


def network_check(height: int, device: torch.device) -> list[dict[str, Any]]:
    """The authors' network with random weights: saved raw, loaded by dpi, run on one map; rows of timings."""
    from dpi.prior.unet import PAPER_CONFIG, UNetModel, count_parameters, load_checkpoint

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "random_256x256.pt"
        torch.save(UNetModel(PAPER_CONFIG).state_dict(), path)
        model = load_checkpoint(path, PAPER_CONFIG, device=device)
    x = torch.randn(1, 3, height, 2 * height, device=device)
    t = torch.full((1,), 500, device=device)
    with torch.no_grad():
        out = model(x, t)
    if tuple(out.shape) != (1, 6, height, 2 * height) or not torch.isfinite(out).all():
        raise RuntimeError(f"network output {tuple(out.shape)}, finite {bool(torch.isfinite(out).all())}")
    detail = f"{count_parameters(model) / 1e6:.1f} M params, map {height}x{2 * height}, out {tuple(out.shape)}"

    def forward() -> None:
        with torch.no_grad():
            model(x, t)

    def forward_backward() -> None:
        xg = x.clone().requires_grad_(True)
        model(xg, t).square().mean().backward()

    rows = [{"part": "network forward fp32", "seconds": timed(forward, 10, device), "detail": detail},
            {"part": "network forward+backward fp32", "seconds": timed(forward_backward, 5, device), "detail": detail}]
    if device.type == "cuda":
        with torch.autocast("cuda", dtype=torch.bfloat16):
            rows.append({"part": "network forward bf16", "seconds": timed(forward, 10, device), "detail": detail})
    return rows


def demo_capture(root: Path) -> Path:
    """The bundled demo as a study scene: copied under root/captures, validated into capture.json."""
    from dpi.preprocess.derive import normalise_capture

    layout = Layout.of_study(root)
    if not layout.capture_dir("demo").exists():
        shutil.copytree(DEMO, layout.capture_dir("demo"))
    files = layout.scene("demo")
    if not files.capture_json.exists():
        normalise_capture(layout.capture_dir("demo"), files.capture_json)
    return files.capture_json


def scene_rows(root: Path, scene: str, config: dict, threads: int,
               sampler: str | None = None) -> list[dict[str, Any]]:
    """Init (unless one is there), one dps sample (with `sampler`, else the config's) and its evaluation of one
    scene under `config`; a row per stage with its metrics."""
    from dataclasses import replace

    from dpi.stages import StageJob, evaluate_stage, init_stage, sample_stage
    from dpi.studies.engine import Job

    start = time.perf_counter()
    demo_capture(root) if scene == "demo" else prepare_capture(root, scene, SCENES[scene][1], threads)
    files = Layout.of_study(root).scene(scene)
    dps = {**job_settings(config["method_params"]["dps"]), **({"sampler": sampler} if sampler else {})}
    synth = SCENES[scene][1] if scene in SCENES else {}
    job = StageJob(Job(root, scene, "", synth, "dps", "", 0, dps, config).pipeline, scene, "dps", 0, threads,
                   progress=False)
    rows = [{"part": "capture", "seconds": time.perf_counter() - start, "detail": ""}]
    if files.sample_files(INIT)["trace"].exists():  # made before (here or carried from another machine)
        rows.append({"part": "init", "seconds": float("nan"), "detail": "reused"})
    else:
        start = time.perf_counter()
        init_stage(replace(job, method=INIT))
        rows.append({"part": "init", "seconds": time.perf_counter() - start,
                     "detail": f"{config['init']['iterations']} iterations"})
    start = time.perf_counter()
    sample_stage(job)
    trace = json.loads(files.sample_files("dps", 0)["trace"].read_text())
    rows.append({"part": "dps sample", "seconds": time.perf_counter() - start,
                 "detail": f"sampler {trace['info'].get('sampler')}, {dps.get('steps')} steps, "
                           f"refine {dps.get('refine', {}).get('iterations')}"})
    start = time.perf_counter()
    evaluate_stage(job)
    metrics = json.loads(job.evaluation.read_text())["metrics"]
    rows.append({"part": "evaluate", "seconds": time.perf_counter() - start,
                 "detail": ", ".join(f"{k} {metrics[k]:.3f}" for k in ("novel_psnr", "env_psnr")
                                     if isinstance(metrics.get(k), float))})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", nargs="+", default=["demo", "blob_sun"], choices=["demo", *SCENES])
    parser.add_argument("--presets", nargs="+", default=["default", "paper"])
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parent, help="folder of the CSV")
    parser.add_argument("--work", type=Path, default=ROOT / "results" / "benchmarks" / "paper_preset_gpu",
                        help="folder of the scenes' captures and results")
    parser.add_argument("--skip-network", action="store_true")
    parser.add_argument("--sampler", default=None, help="dps sampler of the samples (default: the config's)")
    args = parser.parse_args()

    from dpi.config.pipeline import resolve_config
    from dpi.render import backend

    args.out.mkdir(parents=True, exist_ok=True)
    table = args.out / "paper_preset_gpu.csv"
    configs = {preset: resolve_config({"preset": preset}) for preset in args.presets}
    variant = backend.choose_variant(configs[args.presets[-1]]["render"].get("variant", "auto"))
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    threads = os.cpu_count() or 2
    card = torch.cuda.get_device_name() if device.type == "cuda" else "cpu"
    print(f"torch {torch.__version__}, {card}, mitsuba variant {variant}", flush=True)
    rows: list[dict[str, Any]] = []

    def keep(new: list[dict[str, Any]], scene: str, preset: str) -> None:
        for row in new:
            rows.append({"scene": scene, "preset": preset, "variant": variant, "device": card, **row,
                         "commit": current_commit(), "settings_hash": settings_hash(configs.get(preset, preset))})
            print(f"{row['part']:>30} {scene:>9} {preset:>8} {row['seconds']:9.3f} s  {row['detail']}", flush=True)
        with table.open("w", newline="") as f:
            writer = csv.DictWriter(f, (*COLUMNS, *PROVENANCE))
            writer.writeheader()
            writer.writerows(rows)

    parts: list[tuple[str, str, Callable[[], list[dict[str, Any]]]]] = []
    if not args.skip_network:
        paper_height = resolve_config({"preset": "paper"})["problem"]["env_height"]  # the map the authors' net sees
        parts.append(("-", "paper", lambda: network_check(paper_height, device)))
    parts += [(scene, preset, lambda scene=scene, preset=preset: scene_rows(args.work / preset, scene,
                                                                            configs[preset], threads, args.sampler))
              for preset in args.presets for scene in args.scenes]
    for scene, preset, part in parts:
        try:
            keep(part(), scene, preset)
        except Exception:  # a failed part is reported and the next one still runs
            traceback.print_exc()
            keep([{"part": "FAILED", "seconds": float("nan"), "detail": traceback.format_exc()[-300:]}], scene, preset)
    print(f"\n{'part':>30} {'scene':>9} {'preset':>8} {'seconds':>9}")
    for row in rows:
        print(f"{row['part']:>30} {row['scene']:>9} {row['preset']:>8} {row['seconds']:9.2f}")


if __name__ == "__main__":
    main()
