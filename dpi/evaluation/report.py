"""The HTML report of a run (results/report.html): metric table, the paper's Figs. 8-9, and per scene the
input views, env-map samples, textures and re-rendered held-out views of every method.

Static files only: PNGs in a folder next to the page, relative links; it reads offline. The one script is the
3D view's (dpi.evaluation.view3d: model-viewer, copied next to the page, and the exported asset embedded).
It draws from what the workflow wrote (dpi.io.layout), starting at eval/summary.csv: the evaluation's
metric files and held-out renders, the env-map figure of each scene, the samples' textures. It
renders nothing itself.
"""

from __future__ import annotations

import json
import os
import shutil
from html import escape
from pathlib import Path
from urllib.parse import quote

import numpy as np

from dpi.capture import Capture, capture_warnings, complete_capture, read_capture_json, read_ground_truth
from dpi.capture.working import working_capture
from dpi.evaluation.figures import (MethodPoint, Rerender, mask_gallery, quality_diversity_plot, relit_grid,
                                    rerender_grid, roughness_diversity_plot, texture_grid, view_strip)
from dpi.evaluation.metric_table import metric_table, missing_reason, number, read_summary
from dpi.evaluation.relighting import RELIGHT_MAPS, channel_scaled, relit_name
from dpi.evaluation.sample_metrics import masked_srgb
from dpi.evaluation.view3d import install_viewer, view3d_section
from dpi.io.atomic import write_text
from dpi.io.exr import read_exr
from dpi.io.images import read_image, read_mask
from dpi.io.layout import INIT, SAMPLE_TRACE, SUMMARY_FILE, TEXTURE_NAMES, Layout, SceneLayout, texture_file, view_file
from dpi.solve.init import readings_line
from dpi.synth.capture import read_marker

SCALE_ALIGNMENT = (
    "Illumination and albedo are recovered only up to a global scale, so they are compared after scale "
    "alignment (dpi.evaluation.metrics): each env map is multiplied by the one factor exp(mean(log Y_gt - log Y_est)) "
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
p.warning { color: #7a4100; background: #fff3df; border-left: 4px solid #e69500; padding: 4px 8px; font-size: 13px; }
"""


def scene_roughness(capture: Capture) -> float | None:
    """Ground-truth roughness of a scene: its synthetic entry's, else the mean of gt/roughness.exr, else None."""
    marker = read_marker(capture.root)
    if marker is not None:
        return float(marker["roughness"])
    return float(read_ground_truth(capture.gt["roughness"], "roughness").mean()) if "roughness" in capture.gt else None


def recorded_notes(layout: Layout, rows: list[dict[str, str]]) -> dict[str, list[str]]:
    """The `notes` (alignment, pixels compared) recorded in each method's eval/{method}/0.json."""
    notes: dict[str, list[str]] = {}
    for row in rows:
        path = layout.scene(row["scene"]).evaluation(row["method"], 0)
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

    def __init__(self, html: Path, figures: Path, viewer: Path | None = None):
        self.html, self.figures = html, figures
        self.viewer = viewer
        """the 3D views' script next to the page (None: not installed, no 3D view)"""

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
    """The albedo/roughness/metallic arrays among a sample's `files` (name -> EXR) that exist."""
    return {n: read_exr(p) for n, p in files.items() if n in TEXTURE_NAMES and Path(p).is_file()}


def ground_truth_textures(capture: Capture) -> dict[str, np.ndarray]:
    """The capture's ground-truth albedo/roughness/metallic, read as the evaluation reads them."""
    return {n: read_ground_truth(p, n) for n, p in capture.gt.items() if n in TEXTURE_NAMES}


def held_out_rerenders(scene: SceneLayout, capture: Capture, methods: list[str],
                       exposure: float) -> list[tuple[str, np.ndarray, list[Rerender]]]:
    """Per held-out view: the captured image and each method's sample-0 re-render as the evaluation rendered
    and scored it (its eval/{method}/0/ views and PSNRs), with the per-pixel error of the comparison."""
    records = {m: json.loads(scene.evaluation(m, 0).read_text()) for m in methods}
    views = []
    for view in capture.held_out_views:
        captured = read_image(view.image) / exposure
        mask = read_mask(view.mask) if view.mask else np.ones(captured.shape[:2], bool)
        target = masked_srgb(captured, mask)
        row = []
        for method in methods:
            image = read_exr(view_file(scene.evaluation_views(method, 0), view.name))
            error = np.abs(masked_srgb(image, mask) - target).mean(-1)
            row.append(Rerender(method, image, error, records[method]["metrics"]["novel_psnr_views"][view.name]))
        views.append((view.name, captured, row))
    return views


def evaluated_capture(scene: SceneLayout, capture: Capture, method: str) -> Capture:
    """The capture at the size its held-out views were rendered and scored (the working resolution,
    dpi.capture.working): the same downsampled images the evaluation compared against."""
    if not capture.held_out_views:
        return capture
    height, width = read_exr(view_file(scene.evaluation_views(method, 0), capture.held_out_views[0].name)).shape[:2]
    return working_capture(capture, max(width, height), scene.working_dir)


def scene_section(scene_name: str, scene: SceneLayout, rows: list[dict[str, str]], page: Page) -> str:
    """Input views, env-map samples, sample-0 textures and re-rendered held-out views of one scene."""
    methods = [r["method"] for r in rows]
    capture = evaluated_capture(scene, complete_capture(read_capture_json(scene.capture_json), scene), methods[0])
    record = json.loads(scene.evaluation(methods[0], 0).read_text())
    exposure = record["exposure"]
    parts = [f"<h2 id='scene-{escape(scene_name)}'>Scene {escape(scene_name)}</h2>"]
    parts += [f"<p class='warning'><b>Warning:</b> {escape(line)}</p>" for line in capture_warnings(capture)]

    path = page.png(scene_name, "views")
    view_strip([read_image(v.image) / exposure for v in capture.views], [v.name for v in capture.views],
               [v.held_out for v in capture.views], path)
    parts.append(_figure(page.link(path), f"{scene_name} input views",
                         f"The {len(capture.views)} input views (sRGB, at the capture's normalised exposure); "
                         "held-out views, used only for evaluation, are framed and titled in red."))

    parts += mask_gallery_section(scene_name, scene, capture, exposure, page)

    path = page.png(scene_name, "envmaps")
    shutil.copyfile(scene.envmap_figure, path)
    reference = capture.gt.get("envmap")
    parts.append(_figure(page.link(path), f"{scene_name} env maps",
                         "Env-map samples of each method (one row per method, one column per sample), Reinhard "
                         "tone-mapped with gamma 2.2"
                         + (", each aligned to the ground truth's (top row) global scale." if reference else
                            "; the capture has no ground truth.")))

    parts += readings_note(scene)
    if scene.uncertainty_figure.is_file():
        path = page.png(scene_name, "uncertainty")
        shutil.copyfile(scene.uncertainty_figure, path)
        parts.append(_figure(page.link(path), f"{scene_name} uncertainty",
                             "What the samples agree on and where the photos do not tell: per method with two or more "
                             "samples, the geometric mean of its maps, then the per-texel std "
                             "across its samples of the env map's log luminance (each map over its median; 0.7 is a "
                             "factor of 2 either way), of the albedo (each over its mean) and of the roughness. Bright "
                             "is uncertain; summary.csv holds their means (env_log_std, albedo_std, roughness_std), "
                             "env_calibration and the scores of the "
                             "samples' geometric mean map (env_mean_psnr, env_mean_ssim; {method}/env_mean.exr)."))

    parts += view3d_section(scene_name, scene, page.viewer is not None, exposure)

    path = page.png(scene_name, "textures")
    gt = ground_truth_textures(capture)
    texture_grid(([("ground truth", gt)] if gt else [])
                 + [(m, read_textures({n: scene.sample_dir(m, 0) / texture_file(n) for n in TEXTURE_NAMES}))
                    for m in methods], path)
    parts.append(_figure(page.link(path), f"{scene_name} textures",
                         "Albedo (sRGB, as estimated: no scale alignment), roughness and metallic (black 0, white 1) "
                         "of each method's sample 0" + (", ground truth on top." if gt else "; no ground truth.")))

    if capture.held_out_views:
        path = page.png(scene_name, "held_out")
        rerender_grid(held_out_rerenders(scene, capture, methods, exposure), path)
        parts.append(_figure(page.link(path), f"{scene_name} held-out views",
                             "Held-out views as the evaluation re-rendered them with each method's sample 0, the "
                             "view's PSNR in the title, and the per-pixel error: mean absolute sRGB difference over "
                             "the foreground (background 0), one colour scale for the figure."))
        relit = relit_rows(scene, capture, methods)
        if relit:
            path = page.png(scene_name, "relit")
            relit_grid(relit, path)
            parts.append(_figure(page.link(path), f"{scene_name} relit views",
                                 "The first held-out view relit under dpi's relighting maps: the true materials, "
                                 "then each method's sample 0, each scaled per channel to the truth as "
                                 "relight_psnr_h / _l / relight_ssim score it; one exposure per row."))
    else:
        parts.append("<p class='note'>No held-out views: nothing to re-render.</p>")
    return "\n".join(parts)


def readings_note(scene: SceneLayout) -> list[str]:
    """A note where samples start from both of the init's readings (dpi.solve.init: the views' evidence leaves the
    material open): what it measured and how many samples start from the other reading."""
    trace = scene.sample_files(INIT)["trace"]
    readings = json.loads(trace.read_text())["info"].get("readings", {}) if trace.is_file() else {}
    if not readings.get("other"):
        return []
    started = [t for t in scene.root.glob(f"*/*/{SAMPLE_TRACE}")
               if json.loads(t.read_text())["info"].get("reading") == readings["other"]]
    if not started:
        return []
    return [f"<p class='warning'><b>Two readings.</b> The views leave the material open: the init fitted a rough "
            f"dielectric and a glossy metal ({escape(readings_line(readings))}), and {len(started)} of the samples "
            f"start from the {readings['other']} one; the roughness std below shows where they differ, and "
            "samples.csv names each sample's reading.</p>"]


def mask_title(name: str, view: dict) -> str:
    """A gallery title: the view's name and its mask's witnesses (dpi.preprocess.mask_confidence) that were measured."""
    witnesses = [f"{label} {view[key]:.2f}" if isinstance(view[key], float) else f"{label} {view[key]}"
                 for key, label in
                 (("point_coverage", "p"), ("edge_support", "e"), ("agreement", "h"), ("frame_contact", "f"))
                 if key in view]
    return "\n".join([name, " ".join(witnesses)]) if witnesses else name


def mask_gallery_section(scene_name: str, scene: SceneLayout, capture: Capture, exposure: float,
                         page: Page) -> list[str]:
    """Where the masks were derived: every photo with its mask's outline and witnesses, and a warning naming the
    views whose masks are unreliable and why (dpi.preprocess.mask_confidence)."""
    summary_file = scene.masks / SUMMARY_FILE
    if not summary_file.is_file():
        return []
    views = json.loads(summary_file.read_text())["views"]
    shown = [v for v in capture.views if v.name in views and v.mask is not None]
    flagged = [not views[v.name].get("reliable", True) for v in shown]
    path = page.png(scene_name, "masks")
    mask_gallery([read_image(v.image) / exposure for v in shown], [read_mask(v.mask) for v in shown],
                 [mask_title(v.name, views[v.name]) for v in shown], flagged, path)
    reasons = "; ".join(f"{v.name}: {views[v.name].get('why', 'unreliable')}" for v, bad in zip(shown, flagged) if bad)
    parts = [f"<p class='warning'><b>Warning:</b> the derived masks of {sum(flagged)} of {len(shown)} views are "
             f"unreliable ({escape(reasons)}). Check them before trusting the decompositions.</p>"] if any(flagged) \
        else []
    parts.append(_figure(page.link(path), f"{scene_name} masks",
                         "The derived masks: each photo with its mask's outline and, below its name, its witnesses: "
                         "the share of the object's sparse points inside it (p), the share of its outline on an "
                         "image edge (e) and its IoU with the hull the masks carve together (h); unreliable masks "
                         "are outlined and framed in red."))
    return parts


def relit_rows(scene: SceneLayout, capture: Capture, methods: list[str]) -> list[tuple[str, list[tuple[str, np.ndarray]]]]:
    """Per relighting map: the truth's and each method's sample-0 relit first held-out view, as the evaluation
    wrote them (aligned to the truth per channel), or nothing where the capture has no true materials."""
    view = capture.held_out_views[0]
    mask = read_mask(view.mask) if view.mask else None
    rows = []
    for light in RELIGHT_MAPS:
        files = [view_file(scene.evaluation_views(m, 0), relit_name(light, view.name)) for m in methods]
        truth = view_file(scene.evaluation_views(methods[0], 0), relit_name(light, view.name, truth=True))
        if not truth.is_file() or not all(f.is_file() for f in files):
            return []
        reference = read_exr(truth)
        fg = np.ones(reference.shape[:2], bool) if mask is None else mask
        rows.append((light, [(label, image * fg[..., None]) for label, image in
                             [("truth", reference)] + [(m, channel_scaled(read_exr(f), reference, fg))
                                                       for m, f in zip(methods, files)]]))
    return rows


def build_report(layout: Layout, out_html: str | Path, figures_dir: str | Path) -> None:
    """Write the report page for the results tree of `layout` and its PNGs into `figures_dir`."""
    page = Page(Path(out_html), Path(figures_dir), install_viewer(Path(figures_dir)))
    rows = read_summary(layout.summary)
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    captures = {s: read_capture_json(layout.scene(s).capture_json) for s in scenes}
    summary = Path(os.path.relpath(layout.summary, layout.results))
    sections = [metrics_section(rows, recorded_notes(layout, rows), summary),
                quality_section(rows, page), roughness_section(rows, captures, page)]
    sections += [scene_section(s, layout.scene(s), [r for r in rows if r["scene"] == s], page) for s in scenes]
    nav = " &middot; ".join(f"<a href='#scene-{escape(s)}'>{escape(s)}</a>" for s in scenes)
    write_text(out_html, "\n".join([
        "<!DOCTYPE html>", "<html lang='en'>", "<head>", "<meta charset='utf-8'>", "<title>dpi report</title>",
        f"<style>{STYLE}</style>",
        *([f"<script src='{page.link(page.viewer)}'></script>"] if page.viewer else []),
        "</head>", "<body>", "<h1>dpi report</h1>",
        f"<p>Scenes: {nav} &middot; <a href='#metrics'>metrics</a> &middot; <a href='#quality'>quality vs "
        "diversity</a> &middot; <a href='#roughness'>roughness vs diversity</a></p>",
        *sections, "</body>", "</html>", ""]))
