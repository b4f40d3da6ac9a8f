"""The lab notebook's tables: dev sweeps against the defaults of their day, the light's design runs and diagnostics
(notebook/README.md), from the CSVs under notebook/results/. benchmarks/doc_tables.py writes them as it writes the
studies'."""

from __future__ import annotations

from functools import partial
from pathlib import Path

from calibration.tables import calibration, fig9_ratios
from posterior.tables import posterior_rows
from table_format import (ALBEDO, BY_METHOD, ENV, FIT, SECONDS, VIEW, Metric, grouped_table, latest, markdown,
                          method_order, read_rows)

from dpi.solve.dps.loop import MAP_PHASES

NOTEBOOK = Path("notebook") / "results"
"""the lab notebook's CSVs: dev sweeps and superseded rows (notebook/README.md)"""


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


def hotdog_true_light(root: Path) -> str:
    """The hotdog's training-view loss per map and materials (notebook/results/dev/hotdog_true_light.csv)."""
    rows = read_rows(root / NOTEBOOK / "dev" / "hotdog_true_light.csv")
    body = [[r["decomposition"], r["materials"], f"{r['training_loss']:.4f}", f"{r['loss_over_init']:.2f}"]
            for r in rows]
    return markdown(["map", "materials", "training-view loss", "over the init's"], body)


def csv_path(root: Path, csv_name: str) -> Path:
    """A notebook CSV by its name under notebook/results/ (`dev/...`, `previous/...` or a diagnostic's)."""
    return root / NOTEBOOK / csv_name


def mean_map(csv_name: str, root: Path) -> str:
    """One sample's env map against the samples' mean map (notebook/scripts/mean_map.py) per posterior-study group and
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
"""the light's broad balance against the init's (notebook/scripts/light_realism.py's BALANCE columns)"""


BALANCE_DESIGN_METRICS = (*DESIGN_METRICS[:-2], *BALANCE_METRICS)
"""the design runs' light columns with the broad balance against the init's in place of how concentrated it is"""


def light_realism(csv_name: str, root: Path, metrics: tuple[Metric, ...] = LIGHT_METRICS) -> str:
    """How real and how well spread the env maps are on the real-light scenes (notebook/scripts/light_realism.py), per
    group, method and sampler, over scenes: each sample's realism distance to held-out real panoramas (less the
    scene's own), the calibration of its samples and their mean map's accuracy."""
    rows = latest(read_rows(csv_path(root, csv_name)), ("scene", "method", "sampler"))
    return grouped_table(rows, BY_METHOD, metrics, rank_by="group", order=method_order)


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


BALANCE_STAGES = ("init", *MAP_PHASES)
"""notebook/scripts/balance_trace.py's stages: the init's map, then a sample's as it forms"""


def balance_trace(root: Path) -> str:
    """Where a dps sample's broad balance of light goes (notebook/scripts/balance_trace.py): the map's log error at 2
    and 8 rows, and over the init's, per group of design scenes, variant and stage, means over the scenes and seeds."""
    rows = [r for r in read_rows(root / NOTEBOOK / "balance_trace.csv", ("scene", "group", "variant", "stage", "label"))
            if r["label"]]
    metrics = tuple(Metric(header, f"{name}_{k}", ".2f", -1) for k in (2, 8)
                    for name, header in (("err", f"log error at {k} rows"), ("over_init", "over the init's")))

    def order(key: tuple) -> tuple:
        return key[0], key[1] != "init", key[1], BALANCE_STAGES.index(key[2].split("@")[0]), key[2]

    return grouped_table(rows, ("group", "variant", "label"), metrics, order=order)


def balance_views(root: Path) -> str:
    """Which 2-row balance the training views prefer under each albedo, and the broad field each albedo holds
    (notebook/scripts/balance_views.py), per group of scenes."""
    rows = read_rows(root / NOTEBOOK / "balance_views.csv", ("scene", "group", "albedo"))
    albedos = ("start", "init", "truth", "truth_roughness", "truth_metallic", "truth_materials", "samples")
    metrics = (Metric("data loss: true map", "loss_true", ".3f"),
               Metric("true map, init's balance", "loss_init_balance", ".3f"),
               Metric("true map, flat balance", "loss_flat", ".3f"),
               Metric("albedo's broad field", "field", ".2f"))
    return grouped_table(rows, ("group", "albedo"), metrics, order=lambda key: (key[0], albedos.index(key[1])))


TABLES = {
    "balance_trace": balance_trace, "balance_views": balance_views, "pinned_light": pinned_light,
    "glossy_cost": glossy_cost,
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
    "data_weight": partial(dev_table, ("data_weight_dev.csv", "data_weight_heldout.csv")),
    "hotdog_light_probes": hotdog_probes,
    "hotdog_true_light": hotdog_true_light,
    "learned_baselines": partial(dev_table, ("learned_baselines_heldout.csv",)),
    "learned_calibration": partial(calibration, csv=NOTEBOOK / "dev" / "learned_baselines_fig9.csv"),
    "learned_fig9": partial(fig9_ratios, csv=NOTEBOOK / "dev" / "learned_baselines_fig9.csv"),
    "defaults_1202": partial(dev_table, ("joint_start_dev.csv", "joint_start_heldout.csv", "defaults_1202_dev.csv",
                                         "defaults_1202_heldout.csv")),
    "light_settle": partial(dev_table, ("light_settle_dev.csv",)),
    "light_settle_realism": partial(light_realism, "dev/light_settle_realism.csv", metrics=BALANCE_DESIGN_METRICS),
    "light_settle_heldout": partial(dev_table, ("light_settle_heldout.csv",)),
    "light_settle_heldout_realism": partial(light_realism, "dev/light_settle_heldout_realism.csv",
                                            metrics=BALANCE_DESIGN_METRICS),
}
"""the notebook's tables by the name their markers use"""
