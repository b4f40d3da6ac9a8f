"""Result tables generated from the committed study CSVs, never typed: each table is a function of its CSV's
rows, written into the documents between the markers `<!-- table:NAME -->` and `<!-- /table:NAME -->`.

    python benchmarks/doc_tables.py            # regenerate every table of the documents (`make tables`)
    python benchmarks/doc_tables.py --check    # change nothing; exit 2 when a table is out of date

The documentation's tool, not the library's: no module of dpi/ writes a document."""

from __future__ import annotations

import argparse
import math
import re
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

from dpi.io.layout import INIT
from dpi.solve.dps.loop import MAP_PHASES
from dpi.solve.dps.start import GLOSSY_REFINE_FACTOR
from dpi.solve.methods import METHODS
from dpi.studies.engine import latest, read_rows

RESULTS = Path("benchmarks") / "results"
NOTEBOOK = Path("notebook") / "results"
"""the lab notebook's CSVs: dev sweeps and superseded rows (notebook/README.md)"""
"""the committed study CSVs, relative to a checkout's root"""
DOCUMENTS = (Path("README.md"), Path("docs") / "studies.md", Path("docs") / "priors.md", Path("notebook") / "log.md",
             Path("notebook") / "studies.md", Path("notebook") / "priors.md")
"""the documents whose tables are generated"""
METHOD_ORDER = (INIT, *METHODS)
"""rows of a method table: the init, then the methods in their registry's order"""

Row = dict[str, Any]


@dataclass(frozen=True)
class Metric:
    """One numeric column of a table: its header, the CSV column, the format, and which way is better."""

    header: str
    column: str
    fmt: str
    better: int = 0
    """+1: higher is better, -1: lower, 0: not ranked (the best per group is bold)"""
    spread: bool = True
    """show `mean ± std` (population std over the group's rows), else the mean only"""


def stats(values: Iterable[Any]) -> tuple[float, float] | None:
    """Mean and population std of the finite numbers among `values`; None when there are none."""
    numbers = [v for v in values if isinstance(v, float) and math.isfinite(v)]
    if not numbers:
        return None
    mean = sum(numbers) / len(numbers)
    return mean, math.sqrt(sum((v - mean) ** 2 for v in numbers) / len(numbers))


def markdown(header: list[str], body: list[list[str]]) -> str:
    """A GitHub markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(cells) + " |" for cells in body])


def grouped_table(rows: list[Row], keys: tuple[str, ...], metrics: tuple[Metric, ...], rank_by: str | None = None,
                  order: Callable[[tuple], Any] | None = None) -> str:
    """Mean (± std) of each metric per distinct value of `keys`, with the row count `n`; within each value of
    `rank_by` (one of the keys, or the whole table) the best mean of a ranked metric is bold."""
    groups: dict[tuple, list[Row]] = {}
    for row in rows:
        groups.setdefault(tuple(row[k] for k in keys), []).append(row)
    ordered = sorted(groups, key=order) if order else list(groups)
    means = {g: {m.column: stats(r[m.column] for r in groups[g]) for m in metrics} for g in ordered}
    best: set[tuple[tuple, str]] = set()
    for m in (m for m in metrics if m.better):
        for part in dict.fromkeys(g[keys.index(rank_by)] if rank_by else None for g in ordered):
            members = [g for g in ordered if rank_by is None or g[keys.index(rank_by)] == part]
            scored = {g: m.better * means[g][m.column][0] for g in members if means[g][m.column]}
            if len(scored) > 1:
                top = max(scored.values())
                best |= {(g, m.column) for g, v in scored.items() if v == top}
    body = []
    for g in ordered:
        cells = [_text(v) for v in g] + [str(len(groups[g]))]
        for m in metrics:
            s = means[g][m.column]
            cell = "-" if s is None else f"{s[0]:{m.fmt}}"
            cell = f"**{cell}**" if (g, m.column) in best else cell
            if s is not None and m.spread and len(groups[g]) > 1:
                cell += f" ± {s[1]:{m.fmt.lstrip('+')}}"
            cells.append(cell)
        body.append(cells)
    return markdown([*keys, "n", *(m.header for m in metrics)], body)


def _text(value: Any) -> str:
    """A key cell: a number as short as it reads (0.05, 128), text as it is."""
    if isinstance(value, float):
        return f"{value:g}"
    return "" if value is None else str(value)


def method_order(key: tuple, method_at: int = 1) -> tuple:
    """Sort key: the keys before the method as they are, then the methods in METHOD_ORDER, then the rest."""
    method = key[method_at]
    rank = METHOD_ORDER.index(method) if method in METHOD_ORDER else len(METHOD_ORDER)
    return (*key[:method_at], rank, *(str(k) for k in key[method_at + 1:]))


BY_METHOD = ("group", "method", "sampler")
"""the rows a study table shows: one per group, method and dps sampler"""
CALIBRATION_KEY = ("scene", "method", "sampler", "repeat")
VIEW = Metric("view PSNR [dB]", "novel_psnr", ".2f", +1)
ENV = Metric("env PSNR [dB]", "env_psnr", ".2f", +1)
ALBEDO = Metric("albedo MSE", "albedo_mse", ".4f", -1, spread=False)
SECONDS = Metric("s/sample", "seconds", ".1f", spread=False)


FIT = Metric("training fit / truth's", "train_fit_over_truth", ".2f")
"""a sample's training-view fit over the truth's (dpi.evaluation.train_fit): 1 is a posterior sample's"""


def posterior_rows(root: Path) -> list[Row]:
    """The posterior study's newest row per scene, method, sampler and seed."""
    return latest(read_rows(root / RESULTS / "posterior_study.csv"), ("scene", "method", "sampler", "seed"))


def posterior(root: Path) -> str:
    """Posterior study, the README's headline: every method (dps with its default sampler) per scene group,
    over scenes and seeds (the training fit: `posterior_full`)."""
    from dpi.io.settings import field_default
    from dpi.solve.dps.config import DPSConfig

    default = field_default(DPSConfig, "sampler")
    rows = [r for r in posterior_rows(root) if r["method"] != "dps" or r["sampler"] == default]
    metrics = (VIEW, ENV, ALBEDO, Metric("relight PSNR-H [dB]", "relight_psnr_h", ".2f", +1), SECONDS)
    return grouped_table(rows, ("group", "method"), metrics, rank_by="group", order=method_order)


def posterior_full(root: Path) -> str:
    """Posterior study with every metric it keeps."""
    metrics = (VIEW, ENV, Metric("env SSIM", "env_ssim", ".3f", +1, spread=False), ALBEDO,
               Metric("relight PSNR-H [dB]", "relight_psnr_h", ".2f", +1),
               Metric("relight PSNR-L [dB]", "relight_psnr_l", ".2f", +1), FIT, SECONDS)
    return grouped_table(posterior_rows(root), BY_METHOD, metrics, rank_by="group", order=method_order)


def dev_table(csv_names: tuple[str, ...], root: Path, keys: tuple[str, ...] = BY_METHOD) -> str:
    """Posterior-study dev runs (notebook/results/dev/; variants are dps sampler labels, other priors'
    SAMPLER@CHECKPOINT) per `keys` (group or scene, method, sampler)."""
    rows = latest([r for name in csv_names for r in read_rows(root / NOTEBOOK / "dev" / name)],
                  ("scene", "method", "sampler", "seed"))
    metrics = (VIEW, ENV, ALBEDO, Metric("relight PSNR-H [dB]", "relight_psnr_h", ".2f", +1), FIT, SECONDS)
    return grouped_table(rows, keys, metrics, rank_by=keys[0], order=method_order)


def hotdog_probes(root: Path) -> str:
    """dps samples on the authors' hotdog under one changed setting each (notebook/results/dev/hotdog_light_probes.csv):
    the loop's and the written map's env PSNR and broad balance, per variant."""
    rows = read_rows(root / NOTEBOOK / "dev" / "hotdog_light_probes.csv")
    metrics = (Metric("loop map: env PSNR [dB]", "loop_env_psnr", ".2f", +1),
               Metric("env PSNR [dB]", "env_psnr", ".2f", +1),
               Metric("log error at 2 rows", "env_balance_2", ".2f", -1),
               Metric("at 8 rows", "env_balance_8", ".2f", -1), SECONDS)
    return grouped_table(rows, ("settings",), metrics)


def contraction(root: Path) -> str:
    """The contraction study (benchmarks/contraction): the samples' light, spread and calibration per view count."""
    rows = read_rows(root / "benchmarks" / "contraction" / "contraction.csv")
    metrics = (Metric("samples", "samples", ".0f", spread=False),
               Metric("env PSNR [dB]", "env_psnr", ".2f", +1, spread=False),
               Metric("mean map: env PSNR [dB]", "env_mean_psnr", ".2f", +1, spread=False),
               Metric("log error at 2 rows", "env_balance_2", ".2f", -1, spread=False),
               Metric("at 8 rows", "env_balance_8", ".2f", -1, spread=False),
               Metric("spread (log std)", "env_log_std", ".3f", spread=False),
               Metric("calibration (1: ideal)", "env_calibration", ".2f", spread=False),
               Metric("training fit / truth's", "train_fit_over_truth", ".2f", spread=False),
               Metric("s/sample", "sample_seconds", ".1f", spread=False))
    return grouped_table(rows, ("views", "method"), metrics)


def csv_path(root: Path, csv_name: str) -> Path:
    """A study CSV by name: `dev/...` and `previous/...` are the notebook's, the rest benchmarks/results'."""
    return root / (NOTEBOOK if csv_name.split("/")[0] in ("dev", "previous") else RESULTS) / csv_name


def mean_map(csv_name: str, root: Path) -> str:
    """One sample's env map against the samples' mean map (benchmarks/mean_map.py) per posterior-study group and
    method folder: a calibrated sampler pays for its spread on each sample, not on what its samples share."""
    groups = {r["scene"]: r["group"] for r in posterior_rows(root)}
    rows = [{**r, "group": groups.get(r["scene"], ""), "method": r["method"].partition("_")[0],
             "sampler": r["method"].partition("_")[2]}  # a folder is METHOD or dps_SAMPLER
            for r in latest(read_rows(csv_path(root, csv_name)), ("scene", "method"))]
    metrics = (Metric("one sample: env PSNR [dB]", "sample_env_psnr", ".2f", +1),
               Metric("mean map: env PSNR [dB]", "mean_env_psnr", ".2f", +1),
               Metric("one sample: env SSIM", "sample_env_ssim", ".3f", +1, spread=False),
               Metric("mean map: env SSIM", "mean_env_ssim", ".3f", +1, spread=False))
    return grouped_table(rows, BY_METHOD, metrics, rank_by="group", order=method_order)


LIGHT_METRICS = (Metric("realism distance (lower: more real)", "realism", ".3f", -1),
                 Metric("calibration (1: ideal)", "calibration", ".2f"),
                 Metric("mean map: env PSNR [dB]", "env_mean_psnr", ".2f", +1),
                 Metric("mean map: env SSIM", "env_mean_ssim", ".3f", +1, spread=False),
                 Metric("one sample: env PSNR [dB]", "env_psnr", ".2f", +1))
DESIGN_METRICS = (*LIGHT_METRICS[:2], Metric("calibration at 2 rows", "calibration_coarse", ".2f"), *LIGHT_METRICS[2:],
                  Metric("brightest 1 %: share of energy", "peak_share", ".2f"),
                  Metric("the truth's", "peak_share_truth", ".2f", spread=False))
"""the design runs' light columns, with the calibration of the light's broad balance and how concentrated it is"""
BALANCE_METRICS = (*(Metric(f"{which}: log error at {rows} rows / init's", f"balance_{key}_{rows}", ".2f", -1)
                     for which, key in (("mean map", "mean"), ("worst sample", "worst")) for rows in (2, 8)),)
"""the light's broad balance against the init's (benchmarks/light_realism.py's BALANCE columns)"""
BALANCE_DESIGN_METRICS = (*DESIGN_METRICS[:-2], *BALANCE_METRICS)
"""the design runs' light columns with the broad balance against the init's in place of how concentrated it is"""


def light_realism(csv_name: str, root: Path, metrics: tuple[Metric, ...] = LIGHT_METRICS) -> str:
    """How real and how well spread the env maps are on the real-light scenes (benchmarks/light_realism.py), per
    group, method and sampler, over scenes: each sample's realism distance to held-out real panoramas (less the
    scene's own), the calibration of its samples and their mean map's accuracy."""
    rows = latest(read_rows(csv_path(root, csv_name)), ("scene", "method", "sampler"))
    return grouped_table(rows, BY_METHOD, metrics, rank_by="group", order=method_order)


def calibration_rows(root: Path) -> list[dict]:
    """The calibration study's latest rows on the scenes every method was run on (a method run on more scenes
    than the others is compared on the shared ones)."""
    rows = latest(read_rows(root / RESULTS / "calibration_study.csv"), CALIBRATION_KEY)
    methods = {(r["method"], r["sampler"]) for r in rows}
    shared = {scene for scene in {r["scene"] for r in rows}
              if {(r["method"], r["sampler"]) for r in rows if r["scene"] == scene} == methods}
    return [r for r in rows if r["scene"] in shared]


def calibration(root: Path) -> str:
    """Calibration study: metal and rough objects, means over repeats x lights x objects."""
    rows = calibration_rows(root)
    for row in rows:
        row["material"] = "metal" if row["metallic"] >= 0.5 else "rough"
    metrics = (ENV, ALBEDO, Metric("view PSNR [dB]", "novel_psnr", ".2f", +1, spread=False),
               Metric("env sigma2_sample", "env_sigma2_sample", ".4f", spread=False),
               Metric("calibration", "calibration", ".2f"), Metric("s/sample", "seconds", ".0f", spread=False))
    return grouped_table(rows, ("material", "method", "sampler"), metrics, rank_by="material", order=method_order)


def fig9_ratios(root: Path) -> str:
    """Calibration study, Fig. 9: the metal's env sigma2_sample over the rough object's, per object, light and
    repeat (a mirror's samples agree, a rough object's differ); its range per method."""
    rows = calibration_rows(root)
    spread = {(r["object"], r["light"], r["repeat"], r["method"], r["sampler"], r["metallic"] >= 0.5):
              r["env_sigma2_sample"] for r in rows if r["method"] != "init"}
    ratios: dict[tuple, list[float]] = {}
    for (obj, light, repeat, method, sampler, metal), value in spread.items():
        rough = spread.get((obj, light, repeat, method, sampler, False))
        if metal and rough:
            ratios.setdefault((method, sampler), []).append(value / rough)
    body = [[m, s, str(len(v)), f"{min(v):.2f}", f"{max(v):.2f}"]
            for (m, s), v in sorted(ratios.items(), key=lambda kv: method_order(kv[0], 0))]
    return markdown(["method", "sampler", "n", "metal / rough, least", "metal / rough, most"], body)


def train_fit(root: Path) -> str:
    """Training-view fit: each sample's fit over the truth's (posterior study), and the share of samples that fit
    worse than the truth by more than 5 %, per scene group and method."""
    rows = [r for r in posterior_rows(root) if isinstance(r.get("train_fit_over_truth"), float)]
    for row in rows:
        row["above_truth"] = float(row["train_fit_over_truth"] > 1.05)
    metrics = (FIT, Metric("share above 1.05x the truth's", "above_truth", ".2f", spread=False))
    return grouped_table(rows, BY_METHOD, metrics, rank_by="group", order=method_order)


def resolution(root: Path) -> str:
    """Resolution study: dps at each map size, a mirror-like torus and a rough blob."""
    rows = latest(read_rows(root / RESULTS / "resolution_study.csv"), ("scene", "env_height", "texture_size", "seed"))
    for row in rows:
        row["env map"] = f"{int(row['env_height'])} x {2 * int(row['env_height'])}"
    metrics = (VIEW, ENV, Metric("relight PSNR-H [dB]", "relight_psnr_h", ".2f", +1), SECONDS)
    return grouped_table(rows, ("group", "env map"), metrics, rank_by="group",
                         order=lambda k: (k[0], int(k[1].split()[0])))


def roughness(root: Path) -> str:
    """Roughness study (Fig. 9): env sigma2_sample of dps samples per roughness, over repeats."""
    rows = latest(read_rows(root / RESULTS / "roughness_study.csv"), ("roughness", "repeat"))
    return grouped_table(rows, ("roughness", "metallic"),
                         (Metric("env sigma2_sample", "env_sigma2_sample", ".4f"),), order=lambda k: k)


def tradeoff(root: Path) -> str:
    """Presets trade-off: one dps sample of the demo per setting, each changing one knob of `default`."""
    rows = read_rows(root / RESULTS / "tradeoff.csv")
    body = [[r["label"], f"{r['seconds']:.1f}", f"{r['env_psnr']:.2f}", f"{r['albedo_mse']:.4f}",
             f"{r['view_psnr']:.2f}", "yes" if r["pareto"] == "True" else ""] for r in rows]
    return markdown(["setting", "s/sample", "env PSNR [dB]", "albedo MSE", "view PSNR [dB]", "Pareto"], body)


def lens(root: Path) -> str:
    """Lens study: a capture through a barrel lens, undistorted by dpi or its distortion ignored, against its
    pinhole twin; the view PSNR also paired with the twin's of the same seed."""
    rows = latest(read_rows(root / RESULTS / "lens_study.csv", ("variant",)), ("variant", "seed"))
    twin = {r["seed"]: r["novel_psnr"] for r in rows if r["variant"] == "pinhole"}
    for row in rows:
        row["paired"] = row["novel_psnr"] - twin[row["seed"]] if row["seed"] in twin else None
    metrics = (VIEW, Metric("view PSNR - pinhole's [dB]", "paired", "+.2f"), ENV, ALBEDO)
    order = ("pinhole", "undistorted", "ignored")
    return grouped_table(rows, ("variant",), metrics, order=lambda k: order.index(k[0]) if k[0] in order else 9)


def pinned_light(root: Path) -> str:
    """Dev run of dps's pinned light (dpi.solve.dps.loop.seen_weight): each variant's held-out views, env map and
    relighting per study and scene kind (the mirror torus at 128 rows of the resolution study, the posterior
    study's glossy blob and two rough ones, the calibration study's three metals), and the init's."""
    rows = read_rows(root / NOTEBOOK / "dev" / "pinned_light_dev.csv", ("variant", "study", "scene"))
    for row in rows:
        row["kind"] = "rough" if row["scene"] in ("blob_rough", "blob_sun", "blob_room") else "metal"
    order = ("init", "base", "fine_detail", "init_where_seen", "init_where_seen_levelled", "soft_weight",
             "sharpness_weight", "mirror_weight")
    metrics = (Metric("view PSNR [dB]", "novel_psnr", ".2f"), Metric("env PSNR [dB]", "env_psnr", ".2f"),
               Metric("relight PSNR-H [dB]", "relight_psnr_h", ".2f"))
    return grouped_table(rows, ("study", "kind", "variant"), metrics,
                         order=lambda k: (k[0], k[1], order.index(k[2]) if k[2] in order else 9))


def glossy_cost(root: Path) -> str:
    """Dev run of the glossy path's cost: each variant's held-out views, env map, training fit and seconds on the
    posterior study's glossy blob (3 seeds) and the calibration study's metals (repeat 0, 4 samples a row)."""
    rows = read_rows(root / NOTEBOOK / "dev" / "glossy_cost_dev.csv", ("variant", "study", "scene"))
    order = ("levels3_refine2", "levels0_refine2", "levels0_refine1", "levels0_refine1_half_steps",
             "levels0_refine2_one_view", "levels0_refine2_one_view_1024px")
    metrics = (Metric("view PSNR [dB]", "novel_psnr", ".2f"), Metric("env PSNR [dB]", "env_psnr", ".2f"),
               FIT, SECONDS)
    return grouped_table(rows, ("study", "variant"), metrics,
                         order=lambda k: (k[0], order.index(k[1]) if k[1] in order else 9))


def real_photos(root: Path) -> str:
    """Real photo captures end to end (benchmarks/real_photos.py): poses (against a published solution where there
    is one), derived masks against the checked ones and the witnesses' flags, the photo stages' seconds, held-out
    views per method and where a run stopped; the newest row per capture."""
    rows = latest(read_rows(root / RESULTS / "real_photos.csv", ("capture", "size", "stopped")), ("capture",))

    def cell(value: Any, spec: str, scale: float = 1.0) -> str:
        return "-" if not isinstance(value, float) or math.isnan(value) else f"{scale * value:{spec}}"

    body = [[r["capture"], f"{r['views']:.0f} of {r['size']}", f"{r['registered']:.0%}",
             f"{r['reprojection_px']:.2f}" + ("" if cell(r.get("reference_reprojection_px"), ".2f") == "-" else
                                              f" (published {r['reference_reprojection_px']:.2f})"),
             f"{cell(r['rotation_error_deg'], '.2f')} / {cell(r['centre_error'], '.1f', 100)}",
             f"{r['mask_iou']:.3f} (min {r['mask_iou_min']:.2f})",
             f"{r['masks_flagged']:.0f} ({r['flagged_below_08']:.0f} of {r['masks_below_08']:.0f} / "
             f"{cell(r['flagged_below_09'], '.0f')} of {cell(r['masks_below_09'], '.0f')} / "
             f"{r['flagged_above_09']:.0f})",
             " / ".join(cell(r[f"{s}_seconds"], ".0f") for s in ("poses", "masks", "geometry", "uv")),
             " / ".join(cell(r[f"{m}_view_psnr"], ".2f") for m in ("init", "dps", "none")), f"{r['seconds'] / 60:.1f}",
             r["stopped"] or "-"]
            for r in rows]
    return markdown(["capture", "photos", "registered", "reproj. [px]", "vs published: rotation [deg] / centre [%]",
                     "mask IoU vs checked", "flagged (checked: <0.8 / <0.9 / >0.9 IoU)",
                     "poses / masks / geometry / uv [s]", "held-out PSNR init / dps / none [dB]", "min", "stopped at"],
                    body)


def realism(root: Path) -> str:
    """Prior realism on the current held-out real panoramas (the newest rows' settings, which name them): each
    prior's denoising error and NIQE (mean ± std over the maps) on those panoramas, on the real ones it trained on,
    on procedural maps and on its own samples, and each set's realism distance to the held-out panoramas
    (benchmarks/prior_realism.py)."""
    rows = read_rows(root / RESULTS / "prior_realism.csv", ("checkpoint", "family", "kind"))
    current = {r["family"]: r.get("settings_hash") for r in rows}
    rows = latest([r for r in rows if r.get("settings_hash") == current[r["family"]]], ("checkpoint", "kind"))
    kinds = ("real_held_out", "real_train", "procedural", "samples")
    rows.sort(key=lambda r: (r["family"] != "outdoor", kinds.index(r["kind"]) if r["kind"] in kinds else 9,
                             r["checkpoint"]))
    body = [[r["family"], r["kind"], f"`{r['checkpoint']}`", f"{r['maps']:.0f}",
             f"{r['denoising_mse']:.4f} ± {r['denoising_mse_std']:.4f}", f"{r['niqe']:.2f} ± {r['niqe_std']:.2f}",
             f"{r['realism']:.3f}" if isinstance(r.get("realism"), float) else "-"] for r in rows]
    return markdown(["family", "maps", "prior", "n", "denoising MSE (lower: likelier)",
                     "NIQE (lower: more photo-like)", "realism distance to held-out real (lower: closer)"], body)


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


def readings_forced(root: Path) -> str:
    """Readings study, --forced: per scene, each reading's init alone and its dps samples (held-out views, env
    PSNR), with the closing-loss ratio (glossy over rough)."""
    rows = read_rows(root / RESULTS / "readings_forced.csv")
    body = []
    for scene in sorted({r["scene"] for r in rows}, key=lambda s: (s.split("_")[1], s.split("_")[2], s)):
        sel = [r for r in rows if r["scene"] == scene]
        loss = {r["reading"]: r["closing_loss"] for r in sel if r["method"] == "init"}
        if len(loss) < 2:
            continue
        ratio = loss["glossy"] / loss["rough"]
        cells = [scene, f"{ratio:.2f}"]
        for reading in ("rough", "glossy"):
            init = [r for r in sel if r["reading"] == reading and r["method"] == "init"]
            dps = [r for r in sel if r["reading"] == reading and r["method"] == "dps"]
            views = stats(r["novel_psnr"] for r in dps)
            env = stats(r["env_psnr"] for r in dps)
            cells += [f"{init[0]['novel_psnr']:.2f}", f"{views[0]:.2f}" if views else "-",
                      f"{env[0]:.2f}" if env else "-"]
        body.append(cells)
    return markdown(["scene", "closing loss, glossy / rough", "rough: init views [dB]",
                     "rough: dps views [dB]", "rough: dps env [dB]", "glossy: init views [dB]", "glossy: dps views [dB]",
                     "glossy: dps env [dB]"], body)


def readings(root: Path) -> str:
    """Readings study: per scene, means over repeats of the init and of its dps samples, and the share of samples
    that started from the glossy reading."""
    rows = latest(read_rows(root / RESULTS / "readings_study.csv"), ("scene", "repeat"))
    metrics = (Metric("closing loss, glossy / rough (half-way where one stopped)", "ratio", ".2f", spread=False),
               Metric("samples from the glossy reading", "glossy_samples", ".2f", spread=False),
               Metric("init: views [dB]", "init_novel_psnr", ".2f", spread=False),
               Metric("samples: views [dB]", "novel_psnr", ".2f"),
               Metric("worst sample: views [dB]", "min_novel_psnr", ".2f", spread=False),
               Metric("init: env [dB]", "init_env_psnr", ".2f", spread=False),
               Metric("samples: env [dB]", "env_psnr", ".2f"),
               Metric("worst sample: env [dB]", "min_env_psnr", ".2f", spread=False),
               Metric("mean map: env [dB]", "env_mean_psnr", ".2f", spread=False),
               Metric("calibration", "calibration", ".2f", spread=False),
               Metric("init s", "init_seconds", ".0f", spread=False))
    return grouped_table(rows, ("light", "views", "roughness"), metrics, order=lambda k: k)


def readings_fig9(root: Path) -> str:
    """Readings study, Fig. 9: per light and views, the metal's (0.05) env sigma2_sample over the 0.8 dielectric's,
    per repeat."""
    rows = latest(read_rows(root / RESULTS / "readings_study.csv"), ("scene", "repeat"))
    spread = {(r["light"], r["views"], r["repeat"], r["roughness"]): r["env_sigma2_sample"] for r in rows}
    body = []
    for light, views in sorted({(r["light"], r["views"]) for r in rows}):
        ratios = [spread[(light, views, rep, 0.05)] / spread[(light, views, rep, 0.8)]
                  for rep in sorted({r["repeat"] for r in rows})
                  if (light, views, rep, 0.05) in spread and spread.get((light, views, rep, 0.8))]
        if ratios:
            body.append([light, views, str(len(ratios)), " / ".join(f"{x:.2f}" for x in ratios)])
    return markdown(["light", "views", "n", "metal / rough env sigma2_sample, per repeat"], body)


def readings_evidence(root: Path) -> str:
    """Readings study: every scene repeat where both readings finished, with the closing-loss ratio, the evidence's
    log Bayes factor and what the samples made of it."""
    rows = latest(read_rows(root / RESULTS / "readings_study.csv"), ("scene", "repeat"))
    body = [[r["scene"], f"{r['repeat']:.0f}", "metal" if r["metallic"] else "dielectric", f"{r['ratio']:.2f}",
             f"{r['log_bayes_factor']:+.0f}", f"{r['glossy_samples']:.2f}", f"{r['init_novel_psnr']:.2f}",
             f"{r['min_novel_psnr']:.2f}", f"{r['init_env_psnr']:.2f}", f"{r['min_env_psnr']:.2f}"]
            for r in sorted(rows, key=lambda r: (r["scene"], r["repeat"])) if not r["stopped"]]
    return markdown(["scene", "repeat", "truth", "closing loss, glossy / rough", "log Bayes factor, glossy / rough",
                     "samples from the glossy reading", "init: views [dB]", "worst sample: views [dB]",
                     "init: env [dB]", "worst sample: env [dB]"], body)


def readings_cost(root: Path) -> str:
    """Readings study, --cost: the init's seconds with both readings over the rough one's alone, per scene, and
    whether one of the two fits stopped half-way."""
    rows = latest(read_rows(root / RESULTS / "readings_cost.csv"), ("scene", "reading"))
    seconds = {(r["scene"], r["reading"]): r for r in rows}
    body = [[scene, f"{seconds[(scene, 'rough')]['seconds']:.1f}", f"{seconds[(scene, 'auto')]['seconds']:.1f}",
             f"{seconds[(scene, 'auto')]['seconds'] / seconds[(scene, 'rough')]['seconds']:.2f}",
             "yes" if seconds[(scene, "auto")]["stopped"] else "no"]
            for scene in sorted({r["scene"] for r in rows}) if (scene, "rough") in seconds and (scene, "auto") in seconds]
    return markdown(["scene", "rough reading alone [s]", "both readings [s]", "ratio", "one stopped half-way"], body)


def mask_witnesses(root: Path) -> str:
    """Synthetic photo captures (benchmarks/preprocess_accuracy.py --out .../mask_witnesses.csv): derived masks
    against the truth, and what the masks' witnesses flagged, per shape and sweep."""
    rows = latest(read_rows(root / RESULTS / "mask_witnesses.csv", ("shape", "background", "elevations_deg")),
                  ("shape", "background", "views", "size", "arc_deg", "stereo"))
    body = [[r["shape"], r["background"], f"{r['views']:g} of {r['size']:g} px", f"{r['arc_deg']:g}",
             *([f"{r['mask_iou']:.3f}", f"{r['mask_iou_min']:.3f}",
                f"{r['flagged_below_08']:g} of {r['masks_below_08']:g}", f"{r['flagged_above_09']:g}", "-"]
               if not r["error"] else ["-", "-", "-", "-", r["error"]])]
            for r in sorted(rows, key=lambda r: (r["arc_deg"], r["shape"]))]
    return markdown(["shape", "backdrop", "views", "sweep [deg]", "mask IoU", "min", "flagged, views under 0.8",
                     "flagged, views over 0.9", "stopped"], body)


BALANCE_STAGES = ("init", *MAP_PHASES)
"""benchmarks/balance_trace.py's stages: the init's map, then a sample's as it forms"""


def balance_trace(root: Path) -> str:
    """Where a dps sample's broad balance of light goes (benchmarks/balance_trace.py): the map's log error at 2 and 8
    rows, and over the init's, per group of design scenes, variant and stage, means over the scenes and seeds."""
    rows = [r for r in read_rows(root / RESULTS / "balance_trace.csv", ("scene", "group", "variant", "stage", "label"))
            if r["label"]]
    metrics = tuple(Metric(header, f"{name}_{k}", ".2f", -1) for k in (2, 8)
                    for name, header in (("err", f"log error at {k} rows"), ("over_init", "over the init's")))

    def order(key: tuple) -> tuple:
        return key[0], key[1] != "init", key[1], BALANCE_STAGES.index(key[2].split("@")[0]), key[2]

    return grouped_table(rows, ("group", "variant", "label"), metrics, order=order)


def balance_views(root: Path) -> str:
    """Which 2-row balance the training views prefer under each albedo, and the broad field each albedo holds
    (benchmarks/balance_views.py), per group of scenes."""
    rows = read_rows(root / RESULTS / "balance_views.csv", ("scene", "group", "albedo"))
    albedos = ("start", "init", "truth", "truth_roughness", "truth_metallic", "truth_materials", "samples")
    metrics = (Metric("data loss: true map", "loss_true", ".3f"),
               Metric("true map, init's balance", "loss_init_balance", ".3f"),
               Metric("true map, flat balance", "loss_flat", ".3f"),
               Metric("albedo's broad field", "field", ".2f"))
    return grouped_table(rows, ("group", "albedo"), metrics, order=lambda key: (key[0], albedos.index(key[1])))


def seams(root: Path) -> str:
    """The albedo's seam ratio (benchmarks/seams.py) per capture, scene and method: mean and worst over seeds, with
    the given mesh's faces, the atlas's and its texture size."""
    rows = read_rows(root / RESULTS / "seams.csv", ("capture", "scene", "method"))
    worst: dict[tuple, float] = {}
    for row in rows:
        key = (row["capture"], row["scene"], row["method"])
        worst[key] = max(worst.get(key, -math.inf), row["albedo_seam"])
    rows = [{**row, "worst": worst[(row["capture"], row["scene"], row["method"])]} for row in rows]
    shown = (Metric("albedo seam ratio", "albedo_seam", ".2f", -1), Metric("worst", "worst", ".2f", 0, spread=False),
             *(Metric(header, column, ".0f", 0, spread=False) for header, column in
               (("given faces", "given_faces"), ("atlas faces", "faces"), ("texture size", "texture_size"))))
    return grouped_table(rows, ("capture", "scene", "method"), shown, rank_by="scene", order=method_order)


def sun_size(root: Path) -> str:
    """The written sun's size the training views chose (benchmarks/sun_size.py), per scene over its samples."""
    rows = read_rows(root / RESULTS / "sun_size.csv", ("scene",))
    metrics = (Metric("radius written [deg]", "radius_deg", ".2f", 0),
               Metric("views' loss: chosen / own size", "loss_ratio", ".2f", -1),
               Metric("training fit / truth's", "train_fit_over_truth", ".2f", -1), ENV, VIEW)
    return grouped_table(rows, ("scene",), metrics)


def hotdog(root: Path) -> str:
    """The authors' capture at the defaults, a row per method (benchmarks/hotdog/hotdog.py)."""
    rows = read_rows(root / "benchmarks" / "hotdog" / "hotdog.csv", ("method",))
    metrics = (Metric("samples", "samples", ".0f"), VIEW, ENV, Metric("mean map env PSNR [dB]", "env_mean_psnr", ".2f", +1),
               Metric("mean map log error, 2 rows", "env_mean_balance_2", ".2f", -1),
               Metric("at 8 rows", "env_mean_balance_8", ".2f", -1), Metric("calibration", "env_calibration", ".2f"),
               Metric("s/sample", "sample_seconds", ".1f"))
    return grouped_table(rows, ("method",), metrics, order=lambda key: method_order(key, 0))


TABLES: dict[str, Callable[[Path], str]] = {
    "hotdog": hotdog,
    "seams": seams,
    "balance_trace": balance_trace, "balance_views": balance_views,
    "readings": readings, "readings_forced": readings_forced, "readings_fig9": readings_fig9,
    "readings_evidence": readings_evidence, "readings_cost": readings_cost, "mask_witnesses": mask_witnesses,
    "presets": presets, "posterior": posterior, "posterior_full": posterior_full, "calibration": calibration,
    "fig9": fig9_ratios, "train_fit": train_fit, "resolution": resolution, "roughness": roughness,
    "tradeoff": tradeoff, "lens": lens, "realism": realism, "real_photos": real_photos, "pinned_light": pinned_light,
    "glossy_cost": glossy_cost, "sun_size": sun_size,
    "prior_size": partial(dev_table, ("prior64_dev.csv",)),
    "prior_real": partial(dev_table, ("prior32_real_dev.csv",)),
    "sun_fit": partial(dev_table, ("fit_sun_dev.csv", "sun_refine_dev.csv"), keys=("scene", "method", "sampler")),
    "glossy_cost_seeds": partial(dev_table, ("glossy_cost_seeds.csv",)),
    "mean_map": partial(mean_map, "mean_map_posterior.csv"),
    "light_realism": partial(light_realism, "light_realism.csv"),
    "light_balance_ratios": partial(light_realism, "light_realism.csv", metrics=BALANCE_METRICS),
    "light_start": partial(dev_table, ("light_start_dev.csv",)),
    "light_start_realism": partial(light_realism, "dev/light_start_realism.csv"),
    "light_push": partial(dev_table, ("light_prior_perturb_dev.csv",)),
    "light_push_realism": partial(light_realism, "dev/light_push_realism.csv"),
    "light_push_mean_map": partial(mean_map, "dev/light_push_mean_map.csv"),
    "light_design": partial(dev_table, ("light_grain_dev.csv", "light_mix_dev.csv", "light_prior_dev.csv",
                                         "light_sun_dev.csv")),
    "light_design_realism": partial(light_realism, "dev/light_design_realism.csv", metrics=DESIGN_METRICS),
    "light_profile_realism": partial(light_realism, "dev/light_profile_realism.csv", metrics=DESIGN_METRICS),
    "light_balance": partial(dev_table, ("light_balance_dev.csv",)),
    "light_balance_realism": partial(light_realism, "dev/light_balance_realism.csv", metrics=DESIGN_METRICS),
    "light_trade": partial(dev_table, ("light_trade_dev.csv",)),
    "light_trade_realism": partial(light_realism, "dev/light_trade_realism.csv", metrics=DESIGN_METRICS),
    "light_trade_heldout": partial(dev_table, ("light_trade_heldout.csv",)),
    "light_trade_heldout_realism": partial(light_realism, "dev/light_trade_heldout_realism.csv",
                                           metrics=BALANCE_DESIGN_METRICS),
    "light_pin": partial(dev_table, ("light_pin_dev.csv",)),
    "light_pin_realism": partial(light_realism, "dev/light_pin_realism.csv", metrics=BALANCE_DESIGN_METRICS),
    "demo_pixels": partial(dev_table, ("demo_pixels.csv",)),
    "refine_length": partial(dev_table, ("refine_length_dev.csv", "refine_length_heldout.csv")),
    "contraction": contraction,
    "data_weight": partial(dev_table, ("data_weight_dev.csv", "data_weight_heldout.csv")),
    "hotdog_light_probes": hotdog_probes,
    "defaults_1202": partial(dev_table, ("joint_start_dev.csv", "joint_start_heldout.csv", "defaults_1202_dev.csv",
                                         "defaults_1202_heldout.csv")),
    "light_settle": partial(dev_table, ("light_settle_dev.csv",)),
    "light_settle_realism": partial(light_realism, "dev/light_settle_realism.csv", metrics=BALANCE_DESIGN_METRICS),
    "light_settle_heldout": partial(dev_table, ("light_settle_heldout.csv",)),
    "light_settle_heldout_realism": partial(light_realism, "dev/light_settle_heldout_realism.csv",
                                            metrics=BALANCE_DESIGN_METRICS),
}
"""every generated table by the name its markers use"""

MARKER = re.compile(r"(<!-- table:(?P<name>[\w-]+) -->\n)(?P<body>.*?)(<!-- /table:(?P=name) -->)", re.S)


def render_document(text: str, root: Path) -> str:
    """`text` with each marked table replaced by its generated one; an unknown name is an error naming it."""
    def table(match: re.Match) -> str:
        name = match["name"]
        if name not in TABLES:
            raise KeyError(f"unknown table {name!r} (known: {', '.join(TABLES)})")
        return f"{match[1]}{TABLES[name](root)}\n{match[4]}"

    return MARKER.sub(table, text)


def update_tables(root: Path, check: bool = False) -> list[Path]:
    """Regenerate the tables of every document under `root` (or, with `check`, change nothing); the documents
    whose tables were (or would be) changed."""
    changed = []
    for relative in DOCUMENTS:
        path = root / relative
        if not path.exists():
            continue
        text = path.read_text()
        new = render_document(text, root)
        if new != text:
            changed.append(path)
            if not check:
                path.write_text(new)
    return changed


def main(argv: list[str] | None = None) -> int:
    """Regenerate (or --check) the tables of the documents under --root."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--root", type=Path, default=Path(__file__).resolve().parent.parent,
                        help="the checkout whose documents and CSVs to use (default: this one)")
    parser.add_argument("--check", action="store_true", help="change nothing; exit 2 when a table is out of date")
    args = parser.parse_args(argv)
    changed = update_tables(args.root, check=args.check)
    for path in changed:
        print(f"{'out of date' if args.check else 'updated'}: {path}")
    return 2 if args.check and changed else 0


if __name__ == "__main__":
    sys.exit(main())
