"""The priors' realism table."""

from __future__ import annotations

from pathlib import Path

from table_format import latest, markdown, read_rows

HERE = Path("benchmarks") / "priors"
"""the study's folder, relative to a checkout's root"""


def realism(root: Path) -> str:
    """Prior realism on the current held-out real panoramas (the newest rows' settings, which name them): each
    prior's denoising error and NIQE (mean ± std over the maps) on those panoramas, on the real ones it trained on,
    on procedural maps and on its own samples, and each set's realism distance to the held-out panoramas
    (benchmarks/priors/prior_realism.py)."""
    rows = read_rows(root / HERE / "prior_realism.csv", ("checkpoint", "family", "kind"))
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


TABLES = {"realism": realism}
"""the study's tables by the name their markers use"""
