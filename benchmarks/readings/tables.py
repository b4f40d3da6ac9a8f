"""The readings study's tables: the two readings weighed, forced, their Fig. 9, evidence and cost."""

from __future__ import annotations

from pathlib import Path

from table_format import Metric, grouped_table, latest, markdown, read_rows, stats

HERE = Path("benchmarks") / "readings"
"""the study's folder, relative to a checkout's root"""


def readings_forced(root: Path) -> str:
    """Readings study, --forced: per scene, each reading's init alone and its dps samples (held-out views, env
    PSNR), with the closing-loss ratio (glossy over rough)."""
    rows = read_rows(root / HERE / "readings_forced.csv")
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
    rows = latest(read_rows(root / HERE / "readings.csv"), ("scene", "repeat"))
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
    rows = latest(read_rows(root / HERE / "readings.csv"), ("scene", "repeat"))
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
    rows = latest(read_rows(root / HERE / "readings.csv"), ("scene", "repeat"))
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
    rows = latest(read_rows(root / HERE / "readings_cost.csv"), ("scene", "reading"))
    seconds = {(r["scene"], r["reading"]): r for r in rows}
    body = [[scene, f"{seconds[(scene, 'rough')]['seconds']:.1f}", f"{seconds[(scene, 'auto')]['seconds']:.1f}",
             f"{seconds[(scene, 'auto')]['seconds'] / seconds[(scene, 'rough')]['seconds']:.2f}",
             "yes" if seconds[(scene, "auto")]["stopped"] else "no"]
            for scene in sorted({r["scene"] for r in rows}) if (scene, "rough") in seconds and (scene, "auto") in seconds]
    return markdown(["scene", "rough reading alone [s]", "both readings [s]", "ratio", "one stopped half-way"], body)


TABLES = {"readings": readings, "readings_forced": readings_forced, "readings_fig9": readings_fig9, "readings_evidence": readings_evidence, "readings_cost": readings_cost}
"""the study's tables by the name their markers use"""
