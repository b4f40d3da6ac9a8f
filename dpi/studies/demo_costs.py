"""The demo's cost knobs, shared by the trade-off and the step-cost benchmarks: the knobs a preset sets for one
`dps` sample, and the demo capture rendered at another image size."""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cache
from pathlib import Path

from dpi.config.pipeline import Pipeline, resolve_config
from dpi.io.layout import SYNTH_MARKER
from dpi.synth.capture import make_synthetic_capture

DEMO = "demo"


@cache
def demo_pipeline() -> Pipeline:
    """dpi's default config (the demo's), as the workflow resolves it."""
    return Pipeline(resolve_config())


@dataclass(frozen=True)
class Setting:
    """The cost knobs of one dps run."""

    steps: int
    spp: int
    resolution: int
    transport_pixels: int
    env_height: int
    texture_size: int | None
    refine_iterations: int


def preset_setting(name: str | None = None) -> Setting:
    """The knobs of the demo under a quality preset (None: the config's own), as the workflow resolves them."""
    pipeline = demo_pipeline() if name is None else Pipeline(resolve_config({"preset": name}))
    dps, solve = pipeline.method_settings("dps"), pipeline.solve_settings()
    return Setting(steps=dps.steps, spp=solve.render.spp, resolution=pipeline.synth_settings(DEMO).width,
                   transport_pixels=dps.proximal.transport.pixels, env_height=solve.problem.env_height,
                   texture_size=solve.problem.texture_size, refine_iterations=dps.refine.iterations)


def capture_at(resolution: int, threads: int, work: Path) -> Path:
    """The demo capture at an image resolution: the demo's own folder at its configured size, else rendered once
    into `work`/captures."""
    pipeline = demo_pipeline()
    demo = pipeline.synth_settings(DEMO)
    own = demo.width == resolution
    folder = pipeline.layout.capture_dir(DEMO) if own else work / "captures" / f"{DEMO}_{resolution}"
    if not (folder / SYNTH_MARKER).exists():
        make_synthetic_capture(folder, replace(demo, width=resolution, height=resolution), threads=threads,
                               progress=False)
    return folder
