"""Pictures for people: env-map grids, input views, textures, re-rendered views and metric plots (PNG)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import cycle
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from dpi.capture import read_ground_truth  # noqa: E402
from dpi.evaluation.metrics import aligned_env  # noqa: E402
from dpi.io.atomic import atomic_path  # noqa: E402
from dpi.io.images import (  # noqa: E402
    linear_to_srgb,
    luminance,
    tonemap,  # noqa: E402
)
from dpi.io.layout import TEXTURE_NAMES  # noqa: E402
from dpi.light.envmap import read_envmap  # noqa: E402
from dpi.solve.exposure import middle_grey_gain  # noqa: E402

HELD_OUT_COLOR = "#d62728"
SCENE_MARKERS = "osD^vPX*"


def save_figure(fig: plt.Figure, path: str | Path) -> None:
    """Write a figure as a PNG (atomically) and close it."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100)
    plt.close(fig)


def _panels(rows: int, columns: int, width: float, height: float) -> np.ndarray:
    """A new figure's (rows, columns) axes of width x height inches each, without ticks."""
    fig, axes = plt.subplots(rows, columns, figsize=(width * columns, height * rows), squeeze=False,
                             layout="constrained")
    for ax in axes.flat:
        ax.set_xticks([])
        ax.set_yticks([])
    return axes


def display_env(env: np.ndarray, reference: np.ndarray | None) -> np.ndarray:
    """Env map aligned to the reference's scale (when given) as the metrics do, else at its own median luminance
    MIDDLE_GREY, Reinhard tone-mapped, gamma 2.2, in [0, 1]: the same picture at any exposure."""
    if reference is not None:
        return aligned_env(env, reference)[0] ** (1 / 2.2)
    return tonemap(middle_grey_gain(luminance(env)) * env) ** (1 / 2.2)


def envmap_grid(rows: list[tuple[str, list[Path]]], path: str | Path, reference: Path | None = None) -> None:
    """PNG grid: one row per (label, env EXRs), ground truth on top when given; maps scale-aligned to it. Every
    map is read by `dpi.light.envmap.read_envmap`, so a ground truth in an authors' layout (256 x 257) is drawn H x 2H."""
    ref = read_ground_truth(reference, "envmap") if reference else None
    table = ([("ground truth", [reference])] if reference else []) + rows
    axes = _panels(len(table), max(len(files) for _, files in table), 2.4, 1.4)
    for r, (label, files) in enumerate(table):
        for c, ax in enumerate(axes[r]):
            if c < len(files):
                ax.imshow(display_env(read_envmap(files[c], log=False), ref), interpolation="nearest")
                ax.set_title(label if len(files) == 1 else f"{label} #{c}", fontsize=8)
            else:
                ax.axis("off")
    save_figure(axes[0][0].figure, path)


def uncertainty_grid(rows: list[tuple[str, np.ndarray, np.ndarray, np.ndarray, np.ndarray]], path: str | Path) -> None:
    """PNG grid: one row per (method, env mean map (H, 2H, 3), env log-luminance std (H, 2H), albedo std (H, W),
    roughness std (H, W)):
    what the samples agree on, then where they differ, on one colour scale per std column shared by the
    methods, with a colour bar, so a brighter map is a less certain method."""
    axes = _panels(len(rows), 4, 3.0, 1.7)
    for (method, mean, *_), ax in zip(rows, axes[:, 0]):
        ax.imshow(display_env(mean, None), interpolation="nearest")
        ax.set_title(f"{method}: mean map", fontsize=8)
    for column, (title, top) in enumerate([("env log-luminance std", 2.0), ("albedo std / mean", 0.5),
                                           ("roughness std", 0.5)], start=1):
        vmax = min(top, max(max(float(np.percentile(r[1 + column], 99)) for r in rows), 1e-3))
        for (method, *maps), ax in zip(rows, axes[:, column]):
            shown = ax.imshow(maps[column], cmap="magma", vmin=0, vmax=vmax, interpolation="nearest")
            ax.set_title(f"{method}: {title}", fontsize=8)
        axes[0, column].figure.colorbar(shown, ax=list(axes[:, column]), shrink=0.8)
    save_figure(axes[0][0].figure, path)


def relit_grid(rows: list[tuple[str, list[tuple[str, np.ndarray]]]], path: str | Path) -> None:
    """PNG grid: one row per (light, [(label, linear image)]), the truth first; each row's images share one
    exposure (the first image's 99th percentile at 0.9), sRGB-encoded."""
    axes = _panels(len(rows), max(len(images) for _, images in rows), 1.5, 1.7)
    for (light, images), row in zip(rows, axes):
        level = max(float(np.percentile(images[0][1], 99)), 1e-6) / 0.9
        for (label, image), ax in zip(images, row):
            ax.imshow(np.clip(linear_to_srgb(image / level), 0, 1), interpolation="nearest")
            ax.set_title(f"{light}: {label}", fontsize=7)
        for ax in row[len(images):]:
            ax.axis("off")
    save_figure(axes[0][0].figure, path)


def view_strip(images: list[np.ndarray], names: list[str], held_out: list[bool], path: str | Path,
               columns: int = 8) -> None:
    """PNG of linear (H, W, 3) views in rows of `columns`, sRGB-encoded; held-out views framed and titled in red."""
    columns = min(columns, len(images))
    axes = _panels(math.ceil(len(images) / columns), columns, 1.5, 1.7)
    for ax, image, name, held in zip(axes.flat, images, names, held_out):
        ax.imshow(linear_to_srgb(image), interpolation="nearest")
        ax.set_title(f"{name}\nheld out" if held else name, fontsize=7, color=HELD_OUT_COLOR if held else "black")
        for spine in ax.spines.values():
            spine.set(edgecolor=HELD_OUT_COLOR if held else "black", linewidth=3 if held else 0.5)
    for ax in axes.flat[len(images):]:
        ax.axis("off")
    save_figure(axes[0][0].figure, path)


def mask_gallery(images: list[np.ndarray], masks: list[np.ndarray], titles: list[str], flagged: list[bool],
                 path: str | Path, columns: int = 8) -> None:
    """PNG of linear (H, W, 3) photos, sRGB-encoded, each with its mask's outline: green, or red and a red frame
    where the mask is flagged unreliable."""
    columns = min(columns, len(images))
    axes = _panels(math.ceil(len(images) / columns), columns, 1.5, 1.7)
    for ax, image, mask, title, bad in zip(axes.flat, images, masks, titles, flagged):
        colour = HELD_OUT_COLOR if bad else "#1a9850"
        ax.imshow(linear_to_srgb(image), interpolation="nearest")
        if mask.any() and not mask.all():
            ax.contour(mask.astype(float), levels=[0.5], colors=[colour], linewidths=1.0)
        ax.set_title(title, fontsize=7, color=HELD_OUT_COLOR if bad else "black")
        for spine in ax.spines.values():
            spine.set(edgecolor=colour if bad else "black", linewidth=3 if bad else 0.5)
    for ax in axes.flat[len(images):]:
        ax.axis("off")
    save_figure(axes[0][0].figure, path)


def texture_grid(rows: list[tuple[str, dict[str, np.ndarray]]], path: str | Path) -> None:
    """PNG grid: one row per (label, textures); albedo sRGB-encoded, roughness and metallic grey in [0, 1]."""
    axes = _panels(len(rows), len(TEXTURE_NAMES), 1.8, 1.9)
    for (label, textures), row in zip(rows, axes):
        for name, ax in zip(TEXTURE_NAMES, row):
            ax.set_title(f"{label}: {name}", fontsize=8)
            if name not in textures:
                ax.axis("off")
            elif name == "albedo":
                ax.imshow(linear_to_srgb(textures[name]), interpolation="nearest")
            else:
                ax.imshow(textures[name][..., 0], cmap="gray", vmin=0, vmax=1, interpolation="nearest")
    save_figure(axes[0][0].figure, path)


@dataclass
class Rerender:
    """One method's re-render of a view (linear), its per-pixel error map and PSNR [dB]."""

    label: str
    image: np.ndarray
    error: np.ndarray
    psnr: float


def rerender_grid(views: list[tuple[str, np.ndarray, list[Rerender]]], path: str | Path) -> None:
    """PNG grid: per (view name, captured image, re-renders) a row of the capture, then each method's
    render and error map (one shared colour scale, with a colour bar)."""
    vmax = max(max(float(np.percentile(r.error, 99)) for _, _, rs in views for r in rs), 1e-3)
    axes = _panels(len(views), 1 + 2 * len(views[0][2]), 1.5, 1.6)
    for (name, captured, rerenders), row in zip(views, axes):
        row[0].imshow(linear_to_srgb(captured), interpolation="nearest")
        row[0].set_title(f"{name}: captured", fontsize=7)
        for r, image_ax, error_ax in zip(rerenders, row[1::2], row[2::2]):
            image_ax.imshow(linear_to_srgb(r.image), interpolation="nearest")
            image_ax.set_title(f"{r.label} ({r.psnr:.1f} dB)", fontsize=7)
            shown = error_ax.imshow(r.error, cmap="magma", vmin=0, vmax=vmax, interpolation="nearest")
            error_ax.set_title(f"{r.label}: error", fontsize=7)
    axes[0][0].figure.colorbar(shown, ax=axes[:, -1].tolist(), label="|sRGB error|", shrink=0.8)
    save_figure(axes[0][0].figure, path)


@dataclass
class MethodPoint:
    """Held-out view PSNR, env sigma2_sample and naturalness (None: not measured) of one (scene, method)."""

    scene: str
    method: str
    psnr: float
    sigma2: float
    naturalness: float | None


def _marker_areas(values: list[float | None], small: float = 30.0, large: float = 300.0) -> list[float]:
    """Marker areas growing linearly with the values; the middle size for None or equal values."""
    known = [v for v in values if v is not None]
    low, high = (min(known), max(known)) if known else (0.0, 0.0)
    middle = (small + large) / 2
    return [middle if v is None or high == low else small + (large - small) * (v - low) / (high - low) for v in values]


def _method_colors(methods: list[str]) -> dict[str, str]:
    """One tab10 colour per method, in first-seen order."""
    unique = list(dict.fromkeys(methods))
    return {m: f"C{i % 10}" for i, m in enumerate(unique)}


def quality_diversity_plot(points: list[MethodPoint], path: str | Path) -> None:
    """Paper Fig. 8: held-out view PSNR (x) vs env-map sigma2_sample (y, log), marker area from naturalness;
    colour per method, marker shape per scene."""
    fig, ax = plt.subplots(figsize=(6.5, 4.5), layout="constrained")
    colors = _method_colors([p.method for p in points])
    markers = dict(zip(dict.fromkeys(p.scene for p in points), cycle(SCENE_MARKERS)))
    for p, area in zip(points, _marker_areas([p.naturalness for p in points])):
        ax.scatter(p.psnr, p.sigma2, s=area, color=colors[p.method], marker=markers[p.scene], alpha=0.75,
                   edgecolors="black", linewidths=0.5)
        ax.annotate(p.method, (p.psnr, p.sigma2), xytext=(5, 4), textcoords="offset points", fontsize=7)
    if all(p.sigma2 > 0 for p in points):
        ax.set_yscale("log")
    handles = [plt.Line2D([], [], ls="", marker="o", color=c, label=m) for m, c in colors.items()]
    if len(markers) > 1:
        handles += [plt.Line2D([], [], ls="", marker=mk, color="grey", label=s) for s, mk in markers.items()]
    ax.legend(handles=handles, fontsize=7, loc="best")
    ax.set(xlabel="held-out view PSNR [dB] (quality)", ylabel="env-map sigma2_sample (diversity)")
    ax.grid(alpha=0.3)
    save_figure(fig, path)


def roughness_diversity_plot(curves: dict[str, dict[str, list[tuple[float, float]]]], path: str | Path) -> None:
    """Paper Fig. 9: env-map sigma2_sample against ground-truth roughness; curves[object][method] holds
    (roughness, sigma2) points, one panel per object, one line per method."""
    fig, axes = plt.subplots(1, len(curves), figsize=(4.5 * len(curves), 3.5), squeeze=False, layout="constrained")
    colors = _method_colors([m for methods in curves.values() for m in methods])
    for ax, (obj, methods) in zip(axes[0], curves.items()):
        for method, points in methods.items():
            x, y = zip(*sorted(points))
            ax.plot(x, y, marker="o", color=colors[method], label=method)
        ax.set(title=obj, xlabel="ground-truth roughness", ylabel="env-map sigma2_sample")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    save_figure(fig, path)
