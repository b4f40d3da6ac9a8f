"""Pictures for people: a grid of environment-map samples per method next to the ground truth."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from dpi.atomic import atomic_path  # noqa: E402
from dpi.exr import read_exr  # noqa: E402
from dpi.metrics import env_scale, resize_area, tonemap  # noqa: E402


def display_env(env: np.ndarray, reference: np.ndarray | None) -> np.ndarray:
    """Env map aligned to the reference's scale (when given), Reinhard tone-mapped, gamma 2.2, in [0, 1]."""
    if reference is not None:
        env = env * env_scale(env, resize_area(reference, *env.shape[:2]))
    return tonemap(env) ** (1 / 2.2)


def envmap_grid(rows: list[tuple[str, list[Path]]], path: str | Path, reference: Path | None = None) -> None:
    """PNG grid: one row per (label, env EXRs), ground truth on top when given; maps scale-aligned to it."""
    ref = read_exr(reference) if reference else None
    table = ([("ground truth", [reference])] if reference else []) + rows
    columns = max(len(files) for _, files in table)
    fig, axes = plt.subplots(len(table), columns, figsize=(2.4 * columns, 1.4 * len(table)), squeeze=False)
    for r, (label, files) in enumerate(table):
        for c in range(columns):
            ax = axes[r][c]
            ax.set_xticks([])
            ax.set_yticks([])
            if c < len(files):
                ax.imshow(display_env(read_exr(files[c]), ref), interpolation="nearest")
                ax.set_title(label if len(files) == 1 else f"{label} #{c}", fontsize=8)
            else:
                ax.axis("off")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100)
    plt.close(fig)
