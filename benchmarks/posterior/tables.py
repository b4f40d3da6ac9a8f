"""The posterior study's tables: the README's headline, every metric, the training-view fit."""

from __future__ import annotations

from pathlib import Path

from dpi.io.layout import INIT
from table_format import Row, ALBEDO, BY_METHOD, ENV, FIT, SECONDS, VIEW, Metric, grouped_table, latest, method_order, read_rows

HERE = Path("benchmarks") / "posterior"
"""the study's folder, relative to a checkout's root"""


def posterior_rows(root: Path) -> list[Row]:
    """The posterior study's newest row per scene, method, sampler and seed."""
    return latest(read_rows(root / HERE / "posterior.csv"), ("scene", "method", "sampler", "seed"))


def posterior(root: Path) -> str:
    """Posterior study, the README's headline: every method drawn on all the study's seeds (dps with its default
    sampler) per scene group, over scenes and seeds; a method with seeds still to draw is in `posterior_full`."""
    from dpi.io.settings import field_default
    from dpi.solve.dps.config import DPSConfig

    default = field_default(DPSConfig, "sampler")
    rows = [r for r in posterior_rows(root) if r["method"] != "dps" or r["sampler"] == default]
    seeds: dict[str, set] = {}
    for row in rows:
        seeds.setdefault(row["method"], set()).add(row["seed"])
    every = set().union(*(s for m, s in seeds.items() if m != INIT))  # the init is one fit a scene
    rows = [r for r in rows if r["method"] == INIT or seeds[r["method"]] == every]
    metrics = (VIEW, ENV, ALBEDO, Metric("relight PSNR-H [dB]", "relight_psnr_h", ".2f", +1), SECONDS)
    return grouped_table(rows, ("group", "method"), metrics, rank_by="group", order=method_order)


def posterior_full(root: Path) -> str:
    """Posterior study with every metric it keeps."""
    metrics = (VIEW, ENV, Metric("env SSIM", "env_ssim", ".3f", +1, spread=False), ALBEDO,
               Metric("relight PSNR-H [dB]", "relight_psnr_h", ".2f", +1),
               Metric("relight PSNR-L [dB]", "relight_psnr_l", ".2f", +1), FIT, SECONDS)
    return grouped_table(posterior_rows(root), BY_METHOD, metrics, rank_by="group", order=method_order)


def train_fit(root: Path) -> str:
    """Training-view fit: each sample's fit over the truth's (posterior study), and the share of samples that fit
    worse than the truth by more than 5 %, per scene group and method."""
    rows = [r for r in posterior_rows(root) if isinstance(r.get("train_fit_over_truth"), float)]
    for row in rows:
        row["above_truth"] = float(row["train_fit_over_truth"] > 1.05)
    metrics = (FIT, Metric("share above 1.05x the truth's", "above_truth", ".2f", spread=False))
    return grouped_table(rows, BY_METHOD, metrics, rank_by="group", order=method_order)


TABLES = {"posterior": posterior, "posterior_full": posterior_full, "train_fit": train_fit}
"""the study's tables by the name their markers use"""
