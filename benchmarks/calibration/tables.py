"""The calibration study's tables: every method's light, albedo and calibration; Fig. 9's ratios."""

from __future__ import annotations

from pathlib import Path

from table_format import ALBEDO, ENV, Metric, grouped_table, latest, markdown, method_order, read_rows

HERE = Path("benchmarks") / "calibration"
"""the study's folder, relative to a checkout's root"""


CALIBRATION_KEY = ("scene", "method", "sampler", "repeat")


def calibration_rows(root: Path, csv: Path = HERE / "calibration.csv") -> list[dict]:
    """The calibration study's latest rows on the scenes every method was run on (a method run on more scenes
    than the others is compared on the shared ones)."""
    rows = latest(read_rows(root / csv), CALIBRATION_KEY)
    methods = {(r["method"], r["sampler"]) for r in rows}
    shared = {scene for scene in {r["scene"] for r in rows}
              if {(r["method"], r["sampler"]) for r in rows if r["scene"] == scene} == methods}
    return [r for r in rows if r["scene"] in shared]


def calibration(root: Path, csv: Path = HERE / "calibration.csv") -> str:
    """Calibration study (or a run of it in `csv`): metal and rough objects, means over repeats x lights x objects."""
    rows = calibration_rows(root, csv)
    for row in rows:
        row["material"] = "metal" if row["metallic"] >= 0.5 else "rough"
    metrics = (ENV, ALBEDO, Metric("view PSNR [dB]", "novel_psnr", ".2f", +1, spread=False),
               Metric("env sigma2_sample", "env_sigma2_sample", ".4f", spread=False),
               Metric("calibration", "calibration", ".2f"), Metric("s/sample", "seconds", ".0f", spread=False))
    return grouped_table(rows, ("material", "method", "sampler"), metrics, rank_by="material", order=method_order)


def fig9_ratios(root: Path, csv: Path = HERE / "calibration.csv") -> str:
    """Calibration study, Fig. 9: the metal's env sigma2_sample over the rough object's, per object, light and
    repeat (a mirror's samples agree, a rough object's differ); its range per method."""
    rows = calibration_rows(root, csv)
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


TABLES = {"calibration": calibration, "fig9": fig9_ratios}
"""the study's tables by the name their markers use"""
