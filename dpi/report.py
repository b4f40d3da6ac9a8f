"""The HTML report of a run (results/report.html): metric table, the paper's Figs. 8-9, and per scene the
input views, env-map samples, textures and re-rendered held-out views of every method.

Static files only: PNGs in a folder next to the page, relative links, no scripts; it reads offline.
Everything is read from the results tree (layout in DESIGN.md), starting at eval/summary.csv.
"""

from __future__ import annotations

import json
import os
from html import escape
from pathlib import Path
from urllib.parse import quote

import numpy as np
import torch

from dpi.atomic import write_text
from dpi.capture import Capture, read_capture_json
from dpi.exr import read_exr
from dpi.figures import (MethodPoint, Rerender, TEXTURE_NAMES, envmap_grid, quality_diversity_plot, rerender_grid,
                         roughness_diversity_plot, texture_grid, view_strip)
from dpi.images import linear_to_srgb
from dpi.metric_table import metric_table, missing_reason, number, read_summary
from dpi.metrics import psnr
from dpi.seeding import seed_for
from dpi.solve.problem import InverseProblem
from dpi.stages import SolveSettings, load_problem
from dpi.synth.capture import read_marker

SUMMARY = Path("eval") / "summary.csv"
SCALE_ALIGNMENT = (
    "Illumination and albedo are recovered only up to a global scale, so they are compared after scale "
    "alignment (dpi.metrics): each env map is multiplied by the one factor exp(mean(log Y_gt - log Y_est)) "
    "over texels (Y: luminance) and Reinhard tone-mapped before PSNR/SSIM; each albedo is scaled per channel "
    "by its least-squares factor before the MSE; sigma2_sample is taken after dividing each env map by its "
    "median luminance and each albedo by its mean.")
STYLE = """
body { font-family: sans-serif; margin: 1.5em; max-width: 1400px; }
img { max-width: 100%; border: 1px solid #ddd; }
table.metrics { border-collapse: collapse; font-size: 12px; display: block; overflow-x: auto; }
table.metrics th, table.metrics td { border: 1px solid #ccc; padding: 2px 6px; text-align: right; white-space: nowrap; }
table.metrics tr.scene-start td { border-top: 2px solid #444; }
td.missing { color: #aaa; background: #f4f4f4; font-style: italic; cursor: help; }
td.best { background: #e3f4e3; }
span.std { color: #777; font-size: 10px; }
p.note { color: #555; font-size: 13px; }
"""


def sample_dir(results: Path, scene: str, method: str, k: int) -> Path:
    """Folder of posterior sample k of a method (the initialisation for method `init`)."""
    return results / scene / "init" if method == "init" else results / scene / method / str(k)


def scene_roughness(capture: Capture) -> float | None:
    """Ground-truth roughness of a scene: its synthetic entry's, else the mean of gt/roughness.exr, else None."""
    marker = read_marker(capture.root)
    if marker is not None:
        return float(marker["roughness"])
    return float(read_exr(capture.gt["roughness"]).mean()) if "roughness" in capture.gt else None


def recorded_notes(results: Path, rows: list[dict[str, str]]) -> dict[str, list[str]]:
    """The `notes` (alignment, pixels compared) recorded in each method's eval/{method}/0.json."""
    notes: dict[str, list[str]] = {}
    for row in rows:
        path = results / row["scene"] / "eval" / row["method"] / "0.json"
        if not path.is_file():
            continue
        for key, text in json.loads(path.read_text())["metrics"].get("notes", {}).items():
            if text not in notes.setdefault(key, []):
                notes[key].append(text)
    return notes


def _figure(src: str, alt: str, caption: str) -> str:
    """An image with its caption."""
    return f'<figure><img src="{src}" alt="{escape(alt)}"><figcaption>{caption}</figcaption></figure>'


class Page:
    """Where the report's PNGs go and how the page links to them."""

    def __init__(self, html: Path, figures: Path):
        self.html, self.figures = html, figures

    def png(self, *parts: str) -> Path:
        """Path of a figure PNG under the figures folder."""
        path = self.figures.joinpath(*parts).with_suffix(".png")
        path.parent.mkdir(parents=True, exist_ok=True)
        return path

    def link(self, path: Path) -> str:
        """Relative, URL-quoted link from the page to a file."""
        return quote(Path(os.path.relpath(path, self.html.parent)).as_posix())


def metrics_section(rows: list[dict[str, str]], notes: dict[str, list[str]], summary: Path) -> str:
    """The metric table with its legend and the scale alignment used."""
    recorded = "".join(f"<li><b>{escape(k)}</b>: {escape('; '.join(v))}</li>" for k, v in notes.items())
    return (f"<h2 id='metrics'>Metrics</h2>\n{metric_table(rows)}\n"
            f"<p class='note'>From <code>{escape(str(summary))}</code>: means over each method's samples "
            "(&plusmn; std). Green bold: best value of a scene's column (&uarr; higher / &darr; lower is better; "
            "sigma2_sample, the spread across samples, is not ranked). Grey: missing, hover for the reason.</p>\n"
            f"<p class='note'><b>Scale alignment.</b> {SCALE_ALIGNMENT}</p>\n"
            + (f"<p class='note'>Recorded with the metrics:</p><ul class='note'>{recorded}</ul>" if recorded else ""))


def quality_section(rows: list[dict[str, str]], page: Page) -> str:
    """Paper Fig. 8: quality (held-out view PSNR) against diversity (env sigma2_sample) per scene and method."""
    points, left_out = [], []
    has_naturalness = bool(rows) and "env_naturalness" in rows[0]
    for row in rows:
        x, y = number(row.get("novel_psnr")), number(row.get("env_sigma2_sample"))
        if x is None or y is None:
            why = missing_reason(row.get("novel_psnr") if x is None else row.get("env_sigma2_sample"))
            left_out.append(f"{row['scene']}/{row['method']} ({why or 'no value'})")
        else:
            points.append(MethodPoint(row["scene"], row["method"], x, y, number(row.get("env_naturalness"))))
    head = "<h2 id='quality'>Quality vs diversity (paper Fig. 8)</h2>\n"
    if not points:
        return head + ("<p class='note'>Not drawn: no (scene, method) has both a held-out view PSNR and an env-map "
                       "sigma2_sample.</p>")
    path = page.png("quality_diversity")
    quality_diversity_plot(points, path)
    if not has_naturalness:
        size = "Marker size is constant: summary.csv has no env_naturalness column."
    elif all(p.naturalness is None for p in points):
        reasons = {missing_reason(r.get("env_naturalness")) or "empty" for r in rows}
        size = f"Marker size is constant: env_naturalness is missing ({escape('; '.join(sorted(reasons)))})."
    else:
        size = "Marker area grows with env_naturalness (larger: more natural); points without it have the middle size."
    caption = (f"Per scene and method: x = mean held-out view PSNR, y = env-map sigma2_sample. {size}"
               + (f" Not plotted: {escape(', '.join(left_out))}." if left_out else ""))
    return head + _figure(page.link(path), "quality vs diversity", caption)


def roughness_section(rows: list[dict[str, str]], captures: dict[str, Capture], page: Page) -> str:
    """Paper Fig. 9: env sigma2_sample against ground-truth roughness for scenes of the same object."""
    head = "<h2 id='roughness'>Roughness vs diversity (paper Fig. 9)</h2>\n"
    scenes = {s: (c.options.get("object"), scene_roughness(c)) for s, c in captures.items()}
    objects: dict[str, set[float]] = {}
    for obj, roughness in scenes.values():
        if obj is not None and roughness is not None:
            objects.setdefault(obj, set()).add(roughness)
    swept = {obj for obj, values in objects.items() if len(values) > 1}
    curves: dict[str, dict[str, list[tuple[float, float]]]] = {}
    for row in rows:
        obj, roughness = scenes[row["scene"]]
        sigma2 = number(row.get("env_sigma2_sample"))
        if obj in swept and sigma2 is not None:
            curves.setdefault(obj, {}).setdefault(row["method"], []).append((roughness, sigma2))
    if not curves:
        return head + ("<p class='note'>Not drawn: this run has no roughness sweep (it needs two or more scenes of "
                       "the same <code>object</code> with different ground-truth roughness, each with an env "
                       "sigma2_sample).</p>")
    path = page.png("roughness_diversity")
    roughness_diversity_plot(curves, path)
    caption = ("Env-map sigma2_sample of each method against the scene's ground-truth roughness (synthetic entry, "
               "else mean of gt/roughness.exr), one panel per object: "
               + escape(", ".join(f"{o} ({len(objects[o])} roughnesses)" for o in curves)) + ".")
    return head + _figure(page.link(path), "roughness vs diversity", caption)


def read_textures(files: dict[str, Path]) -> dict[str, np.ndarray]:
    """The albedo/roughness/metallic arrays among `files` (name -> EXR) that exist."""
    return {n: read_exr(p) for n, p in files.items() if n in TEXTURE_NAMES and Path(p).is_file()}


def rerenders(problem: InverseProblem, scene: str, methods: list[tuple[str, Path]],
              spp: int) -> list[tuple[str, np.ndarray, list[Rerender]]]:
    """Each held-out view re-rendered with each (method, sample folder) as in evaluation (same seeds and spp)."""
    decompositions = [(m, problem.load_decomposition(folder)) for m, folder in methods]
    views = []
    for view in problem.held_out_ids:
        captured, mask = problem.images[view].numpy(), problem.masks[view].numpy()
        target = linear_to_srgb(captured) * mask[..., None]
        row = []
        for method, d in decompositions:
            with torch.no_grad():
                image = problem.render(d.env, d.materials, view, seed_for(scene, method, 0, "eval") + view, spp)
            image = image.numpy()
            ours = linear_to_srgb(image) * mask[..., None]
            row.append(Rerender(method, image, np.abs(ours - target).mean(-1), psnr(ours, target, mask)))
        views.append((problem.views[view].name, captured, row))
    return views


def scene_section(results: Path, scene: str, rows: list[dict[str, str]], page: Page, spp: int,
                  settings: SolveSettings) -> str:
    """Input views, env-map samples, sample-0 textures and re-rendered held-out views of one scene."""
    problem = load_problem(results / scene / "capture.json", settings)
    capture = problem.capture
    samples = [(r["method"], [sample_dir(results, scene, r["method"], k) for k in range(int(r["samples"]))])
               for r in rows]
    parts = [f"<h2 id='scene-{escape(scene)}'>Scene {escape(scene)}</h2>"]

    path = page.png(scene, "views")
    view_strip([im.numpy() for im in problem.images], [v.name for v in problem.views],
               [v.held_out for v in problem.views], path)
    parts.append(_figure(page.link(path), f"{scene} input views",
                         f"The {len(problem.views)} input views (sRGB); held-out views, used only for evaluation, "
                         "are framed and titled in red."))

    path = page.png(scene, "envmaps")
    reference = capture.gt.get("envmap")
    envmap_grid([(m, [d / "envmap.exr" for d in dirs]) for m, dirs in samples], path, reference)
    parts.append(_figure(page.link(path), f"{scene} env maps",
                         "Env-map samples of each method (one row per method, one column per sample), Reinhard "
                         "tone-mapped with gamma 2.2"
                         + (", each aligned to the ground truth's (top row) global scale." if reference else
                            "; the capture has no ground truth.")))

    path = page.png(scene, "textures")
    gt = read_textures(capture.gt)
    texture_grid(([("ground truth", gt)] if gt else [])
                 + [(m, read_textures({n: dirs[0] / f"{n}.exr" for n in TEXTURE_NAMES})) for m, dirs in samples], path)
    parts.append(_figure(page.link(path), f"{scene} textures",
                         "Albedo (sRGB, as estimated: no scale alignment), roughness and metallic (black 0, white 1) "
                         "of each method's sample 0" + (", ground truth on top." if gt else "; no ground truth.")))

    if problem.held_out_ids:
        path = page.png(scene, "held_out")
        rerender_grid(rerenders(problem, scene, [(m, dirs[0]) for m, dirs in samples], spp), path)
        parts.append(_figure(page.link(path), f"{scene} held-out views",
                             f"Held-out views re-rendered with each method's sample 0 ({spp} spp, the evaluation's "
                             "seeds), PSNR of the view in the title, and the per-pixel error: mean absolute sRGB "
                             "difference over the foreground (background 0), one colour scale for the figure."))
    else:
        parts.append("<p class='note'>No held-out views: nothing to re-render.</p>")
    return "\n".join(parts)


def build_report(results_dir: str | Path, out_html: str | Path, figures_dir: str | Path, spp: int,
                 settings: SolveSettings) -> None:
    """Write the report page for the results tree `results_dir` and its PNGs into `figures_dir`."""
    results, page = Path(results_dir), Page(Path(out_html), Path(figures_dir))
    rows = read_summary(results / SUMMARY)
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    captures = {s: read_capture_json(results / s / "capture.json") for s in scenes}
    sections = [metrics_section(rows, recorded_notes(results, rows), SUMMARY),
                quality_section(rows, page), roughness_section(rows, captures, page)]
    sections += [scene_section(results, s, [r for r in rows if r["scene"] == s], page, spp, settings) for s in scenes]
    nav = " &middot; ".join(f"<a href='#scene-{escape(s)}'>{escape(s)}</a>" for s in scenes)
    write_text(out_html, "\n".join([
        "<!DOCTYPE html>", "<html lang='en'>", "<head>", "<meta charset='utf-8'>", "<title>dpi report</title>",
        f"<style>{STYLE}</style>", "</head>", "<body>", "<h1>dpi report</h1>",
        f"<p>Scenes: {nav} &middot; <a href='#metrics'>metrics</a> &middot; <a href='#quality'>quality vs "
        "diversity</a> &middot; <a href='#roughness'>roughness vs diversity</a></p>",
        *sections, "</body>", "</html>", ""]))
