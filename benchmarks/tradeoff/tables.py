"""The presets' table and their cost trade-off."""

from __future__ import annotations

from pathlib import Path

from dpi.solve.dps.start import GLOSSY_REFINE_FACTOR
from table_format import markdown, read_rows

HERE = Path("benchmarks") / "tradeoff"
"""the study's folder, relative to a checkout's root"""


def tradeoff(root: Path) -> str:
    """Presets trade-off: one dps sample of the demo per setting, each changing one knob of `default`."""
    rows = read_rows(root / HERE / "tradeoff.csv")
    body = [[r["label"], f"{r['seconds']:.1f}", f"{r['env_psnr']:.2f}", f"{r['albedo_mse']:.4f}",
             f"{r['view_psnr']:.2f}", "yes" if r["pareto"] == "True" else ""] for r in rows]
    return markdown(["setting", "s/sample", "env PSNR [dB]", "albedo MSE", "view PSNR [dB]", "Pareto"], body)


def presets(root: Path) -> str:
    """The quality presets of dpi's default config, each with the settings it fills (dpi.io.settings.apply_preset)."""
    from copy import deepcopy

    from dpi.config.pipeline import DEFAULT_CONFIG, Pipeline, read_yaml
    from dpi.io.settings import apply_preset

    base = read_yaml(DEFAULT_CONFIG)
    body = []
    for name in base["presets"]:
        pipeline = Pipeline(apply_preset({**deepcopy(base), "preset": name}))
        problem, dps = pipeline.solve_settings().problem, pipeline.method_settings("dps")
        refine = dps.refine.iterations
        body.append([f"`{name}`", str(dps.steps), f"{refine} ({refine * GLOSSY_REFINE_FACTOR} on a glossy object)",
                     str(pipeline.solve_settings().render.spp), str(pipeline.init_settings.iterations),
                     f"{problem.resolution} px" if problem.resolution else "the capture's own",
                     f"{problem.env_height} x {2 * problem.env_height}", str(problem.texture_size or f"the capture's (at most {problem.max_texture_size})")])
    return markdown(["preset", "diffusion steps", "refinement iterations", "spp", "init iterations",
                     "views fitted at (longer side)", "env map", "textures"], body)


TABLES = {"tradeoff": tradeoff, "presets": presets}
"""the study's tables by the name their markers use"""
