"""Path-traced initialisation, the first step of every method: a free env map and materials fitted jointly.

Its roughness and metallic seed every posterior method; its albedo is reset by the methods.
The starting map is uniform, at the level that makes a grey (albedo 0.5) diffuse object match
the mean observed foreground radiance; the textures start constant. Under that uniform map roughness
changes nothing, so a fit from a rough start on a mirror stops half-way, its reflections smeared into the map,
and a fit from a glossy start on a rough object paints the object's shading into the map: each start keeps its
reading. So the init fits two readings, a rough dielectric and a glossy metal. One clearly behind half-way stops
there (its closing loss, BOTH_FINISH); where both finish, the views' evidence for each (dpi.solve.evidence: how well
it explains them, less what its map's freedom costs) gives each its posterior probability, and the samples come
from both in proportion (sample_reading; docs/studies.md, "Two readings").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import torch

from dpi.io.settings import Steps, settings
from dpi.solve.decomposition import Decomposition
from dpi.solve.evidence import glossy_probability, log_evidence
from dpi.solve.materials import MaterialTextures
from dpi.solve.optimize import CHECKPOINT_EVERY, AdamFit, FreeEnvMap, OptimizeConfig
from dpi.solve.problem import InverseProblem
from dpi.solve.trace import Trace
from dpi.solve.transport import MAX_TRANSPORT_HEIGHT, TransportConfig, record_transport

START_ALBEDO = 0.5
READINGS = {"rough": (0.5, 0.0), "glossy": (0.1, 1.0)}
"""the two readings the init fits, by their constant (roughness, metallic) start: a rough dielectric and a glossy
metal"""
BOTH_FINISH = (0.45, 0.55)
"""half-way closing-loss ratios (glossy over rough) between which both fits finish; below, the rough fit stops
half-way and the glossy reading is kept alone, at or above the upper bound the glossy fit stops and the rough one is
kept (half-way, the readings study's metals stood at 0.20-0.46 and its dielectrics at 0.53-2.08; the ratio still
moves in the second half, by up to +0.43 on a dielectric, so only those near the line finish both; docs/studies.md,
"Two readings")"""


CLOSING_STEPS = 20
"""steps at the end of a fit whose mean data loss compares two fits (the same seed: the same views and noise)"""


@settings
class InitConfig(OptimizeConfig):
    """The init's fit (config section `init`): Adam settings and the readings fitted."""

    iterations: Steps = 200
    """Adam steps of each reading's fit"""
    reading: Literal["auto", "rough", "glossy"] = "auto"
    """auto: fit a rough dielectric and a glossy metal and sample what explains the views (both, where both do about
    equally); rough or glossy: fit that reading alone, at half the cost"""


def starting_log_env(problem: InverseProblem) -> torch.Tensor:
    """Uniform log-radiance explaining the mean foreground radiance with a grey diffuse object."""
    values = [img[mask].mean() for i in problem.train_ids
              for img, mask in [(problem.images[i], problem.masks[i])]]
    level = max(float(torch.stack(values).mean()) / START_ALBEDO, 1e-4)
    h = problem.settings.env_height
    return torch.full((h, 2 * h, 3), math.log(level))


GLOSSY_ROUGHNESS = 0.3
"""an init whose roughness 25th percentile is below this is glossy"""


def roughness_p25(materials: MaterialTextures) -> float:
    """The roughness texture's 25th percentile (untouched texels keep the start's, so the median misses a shiny
    object)."""
    return float(torch.quantile(materials.roughness.detach().flatten(), 0.25))


METAL_TEXEL = 0.5
"""a texel whose metallic is above this is read as metal (a dps sample's start keeps its metal)"""


def is_glossy(materials: MaterialTextures, threshold: float = GLOSSY_ROUGHNESS) -> bool:
    """True when the roughness 25th percentile is below `threshold`: a shiny object, at least in part."""
    return roughness_p25(materials) < threshold


def starting_materials(init: Decomposition) -> MaterialTextures:
    """Where every posterior method starts: a grey albedo, the init's roughness, and on a rough object
    the init's median metallic everywhere (on a glossy one, `is_glossy`, its metallic texture).

    The init fits a rough object's materials under a blurred light and explains the highlights it cannot place
    with metal, so its metallic texture is a poor start there (notebook/log.md, "the material start"). A mirror's
    views resolve its materials: there the texture starts."""
    materials = init.materials.detached()
    with torch.no_grad():
        materials.albedo.fill_(START_ALBEDO)
        if not is_glossy(materials):
            materials.metallic.fill_(float(materials.metallic.median()))
    return materials


def closing_loss(trace: Trace) -> float:
    """Mean data loss over a fit's last CLOSING_STEPS steps."""
    losses = [step["data"] for step in trace.steps if step.get("data") is not None][-CLOSING_STEPS:]
    return sum(losses) / len(losses) if losses else math.inf


def reading_evidence(problem: InverseProblem, fit: AdamFit, name: str, seed: int) -> float:
    """The views' log evidence under one finished reading (dpi.solve.evidence), from its transport recorded on the
    finest grid, as a sample of that reading records it (every texel drawn for the rough one, the bright ones for the
    glossy one, whose narrow lobe the BSDF samples)."""
    with torch.no_grad():
        env = fit.env_model().exp()
    transport = record_transport(problem, fit.materials, env, TransportConfig(), seed, MAX_TRANSPORT_HEIGHT,
                                 every_texel=name == "rough")
    return log_evidence(transport, env, fit.materials.albedo)


def sample_reading(k: int, readings: dict) -> str:
    """The reading sample k starts from (`readings`: an init trace's record): sample 0 the kept one, and among the
    first n samples the nearest whole number to n x its share (ties down) from the other."""
    other, share = readings.get("other"), readings.get("other_share", 0.0)
    if not other or share <= 0:
        return readings.get("kept", "rough")
    before, through = (math.ceil(n * share - 0.5) for n in (k, k + 1))  # other-reading samples among the first n
    return other if through > before else readings["kept"]


def half_way_stop(ratio: float) -> str | None:
    """The reading whose fit stops half-way, given the closing-loss ratio glossy / rough there (BOTH_FINISH): None
    when both finish."""
    low, high = BOTH_FINISH
    return None if low <= ratio < high else "rough" if ratio < low else "glossy"


def readings_line(record: dict) -> str:
    """One line of what the init's readings found: each closing loss, what stopped half-way or the evidence's log
    Bayes factor, what was kept and the other reading's posterior probability (its share of the samples)."""
    losses = ", ".join(f"{name} {loss:.4g}" for name, loss in record["closing_loss"].items())
    stopped = f"; {record['stopped']} stopped half-way" if record.get("stopped") else ""
    if "log_bayes_factor" in record:
        stopped += f"; log Bayes factor glossy over rough {record['log_bayes_factor']:+.1f}"
    other = f"; the {record['other']} reading's probability {record['other_share']:.2g}" if record["other"] else ""
    return f"closing loss {losses}{stopped}; kept {record['kept']}{other}"


def start_fit(problem: InverseProblem, cfg: InitConfig, reading: str, seed: int) -> AdamFit:
    """The init's fit of one reading from the uniform starting map and that reading's constant (roughness,
    metallic) textures."""
    start = READINGS[reading]
    materials = MaterialTextures.constant(problem.settings.texture_size, START_ALBEDO, *start)
    return AdamFit(problem, FreeEnvMap(starting_log_env(problem)), materials, cfg, seed,
                   Trace(info={"stage": "init", "config": vars(cfg).copy(), "seed": seed, "start": list(start),
                               "reading": reading}))


@dataclass
class InitReadings:
    """The init's result: the kept reading (what every method starts from), the other where samples come from it
    too, and the record of both (also in the kept one's trace: info["readings"])."""

    kept: Decomposition
    other: Decomposition | None
    record: dict


def path_traced_init(problem: InverseProblem, cfg: InitConfig, seed: int, progress: bool = True,
                     checkpoint: Path | None = None, checkpoint_every: int = CHECKPOINT_EVERY) -> InitReadings:
    """Fit env map + materials from each reading of `cfg.reading` (both for auto: the one clearly behind half-way
    stops there, BOTH_FINISH); keep the one most samples come from (the evidence's glossy_probability).
    `checkpoint`: the rough fit's resume file; the glossy fit's is its sibling."""
    names = list(READINGS) if cfg.reading == "auto" else [cfg.reading]
    fits = {name: start_fit(problem, cfg, name, seed) for name in names}
    for name, fit in fits.items():
        fit.resume(checkpoint and (checkpoint if name == "rough" else
                                   checkpoint.with_name(f"{checkpoint.stem}.{name}{checkpoint.suffix}")),
                   checkpoint_every)
    half = cfg.iterations // 2 if len(fits) > 1 else cfg.iterations
    for fit in fits.values():
        fit.run(half, progress)
        fit.save()  # a kill later does not redo this half
    record: dict = {"fitted": names}
    if len(fits) > 1:
        record["half_way_ratio"] = closing_loss(fits["glossy"].trace) / closing_loss(fits["rough"].trace)
        if stopped := half_way_stop(record["half_way_ratio"]):
            record["stopped"] = stopped
    for name, fit in fits.items():
        if record.get("stopped") != name:
            fit.run(cfg.iterations, progress)
            fit.save()
    losses = {name: closing_loss(fit.trace) for name, fit in fits.items()}
    record["closing_loss"] = losses
    if len(fits) == 1:
        record.update(kept=names[0], other=None, other_share=0.0)
    else:
        if "stopped" in record:
            record["ratio"], share, other_share = None, float(record["stopped"] == "rough"), 0.0
        else:
            record["ratio"] = losses["glossy"] / losses["rough"]
            factor = record["log_bayes_factor"] = (reading_evidence(problem, fits["glossy"], "glossy", seed)
                                                   - reading_evidence(problem, fits["rough"], "rough", seed))
            share, other_share = glossy_probability(factor), glossy_probability(-abs(factor))  # the less likely, exactly
        kept = "glossy" if share > 0.5 else "rough"
        other = "rough" if kept == "glossy" else "glossy"
        record.update(kept=kept, other=other if other_share > 0 else None,
                      other_share=other_share, glossy_roughness_p25=roughness_p25(fits["glossy"].materials),
                      rough_roughness_p25=roughness_p25(fits["rough"].materials))
    results = {}
    for name in (record["kept"], record["other"]):
        if name:
            log_env, materials = fits[name].finish()
            fits[name].trace.info["readings"] = record
            results[name] = Decomposition(log_env.exp(), materials, fits[name].trace)
    for name, fit in fits.items():
        if name not in results:
            fit.finish()  # its resume file goes
    return InitReadings(results[record["kept"]], results.get(record["other"]), record)
