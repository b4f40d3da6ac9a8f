"""The HTML report: built from a small fake results tree, every image loads in headless Chromium."""

from __future__ import annotations

import json
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from dpi.capture import read_capture_json
from dpi.evaluation.figures import envmap_grid
from dpi.evaluation.metric_table import direction, metric_table
from dpi.evaluation.relighting import RELIGHT_MAPS, relit_name
from dpi.evaluation.report import Page, build_report, quality_section, roughness_section
from dpi.evaluation.summary import write_csv
from dpi.io.atomic import write_json
from dpi.io.exr import read_exr, write_exr
from dpi.io.layout import INIT, SUMMARY_FILE, Layout, view_file
from dpi.preprocess.derive import normalise_capture
from dpi.stages import Pipeline, StageJob, uncertainty_stage

METHODS = {INIT: 1, "none": 2, "dps": 2}
ROUGHNESS = {"glossy": 0.1, "rough": 0.6}
PROBE = """<script>
window.addEventListener("load", () => {
  for (const img of document.images) img.setAttribute("data-natural-width", img.naturalWidth);
  document.body.setAttribute("data-probed", "yes");
});
</script>"""


def summary_rows(naturalness: bool = True) -> list[dict[str, str]]:
    """summary.csv rows of both scenes: init has one sample; dps is missing an LPIPS value."""
    rows = []
    for s, scene in enumerate(ROUGHNESS):
        for m, (method, samples) in enumerate(METHODS.items()):
            row = {"scene": scene, "method": method, "samples": str(samples), "novel_psnr": f"{20 + m + s}",
                   "novel_psnr_std": "0.5", "novel_lpips": "missing: no LPIPS weights" if method == "dps" else
                   f"{0.1 * (m + 1)}", "albedo_mse": f"{0.01 * (3 - m)}",
                   "env_sigma2_sample": "missing: one sample" if samples == 1 else f"{0.001 * (m + 1) * (s + 1)}"}
            if naturalness:
                row["env_naturalness"] = "missing: one sample" if samples == 1 else f"{m + 2 * s}"
            rows.append(row)
    return rows


def write_summary(path: Path, rows: list[dict[str, str]]) -> None:
    """As the summary stage writes it: missing cells empty, their reasons in `notes`."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_csv(path, rows)


@pytest.fixture(scope="module")
def results(tmp_path_factory, tiny_capture) -> Layout:
    """Two scenes of one object (copies of the tiny capture, roughness 0.1 and 0.6) with random samples, their
    evaluation files (metrics and held-out renders) and env-map figures, as the workflow lays them out."""
    root = tmp_path_factory.mktemp("report")
    layout = Layout(root / "results", root / "captures")
    rng = np.random.default_rng(0)
    gt_env = read_exr(tiny_capture / "gt" / "envmap.exr")
    for name, roughness in ROUGHNESS.items():
        capture = shutil.copytree(tiny_capture, layout.capture_dir(name))
        marker = json.loads(layout.synth_marker(name).read_text())
        layout.synth_marker(name).write_text(json.dumps({**marker, "roughness": roughness}))
        scene = layout.scene(name)
        normalise_capture(capture, scene.capture_json)
        held_out = [v for v in read_capture_json(scene.capture_json).views if v.held_out]
        for method, samples in METHODS.items():
            for k in range(samples):
                files = scene.sample_files(method, k)
                write_exr(files["env"], gt_env[::2, ::2] * rng.uniform(0.5, 2, (4, 8, 3)).astype(np.float32))
                write_exr(files["albedo"], rng.uniform(0.1, 0.9, (8, 8, 3)).astype(np.float32))
                write_exr(files["roughness"], np.full((8, 8, 1), roughness, np.float32))
                write_exr(files["metallic"], np.zeros((8, 8, 1), np.float32))
            for view in held_out:
                names = [view.name] + [relit_name(light, view.name, truth) for light in RELIGHT_MAPS
                                       for truth in (False, True)]
                for name in names:
                    write_exr(view_file(scene.evaluation_views(method, 0), name),
                              rng.uniform(0, 0.5, (24, 24, 3)).astype(np.float32))
            record = {"exposure": 2.0, "metrics": {"notes": {"env": "global log-luminance scale alignment"},
                                                   "novel_psnr_views": {v.name: 20.0 for v in held_out}}}
            scene.evaluation(method, 0).parent.mkdir(parents=True, exist_ok=True)
            scene.evaluation(method, 0).write_text(json.dumps(record))
        envmap_grid([(m, [scene.sample_files(m, k)["env"] for k in range(n)]) for m, n in METHODS.items()],
                    scene.envmap_figure)
        job = StageJob(Pipeline({"results_dir": str(layout.results), "captures_dir": str(layout.captures)}),
                       scene.root.name)
        uncertainty_stage(job, [(m, [scene.sample_dir(m, k) for k in range(n)]) for m, n in METHODS.items() if n >= 2])
    first = layout.scene(next(iter(ROUGHNESS)))  # its masks as the masks stage summarises derived ones
    views = read_capture_json(first.capture_json).views
    flags = {v.name: {"method": "grabcut", "agreement": 0.95, "point_coverage": 0.5 if i == 1 else 1.0,
                      "reliable": i != 1, **({"why": "50% of the object's points fall outside"} if i == 1 else {})}
             for i, v in enumerate(views)}
    write_json(first.masks / SUMMARY_FILE, {"views": flags})
    write_summary(layout.summary, summary_rows())
    return layout


class Images(HTMLParser):
    """The attributes of every <img> and whether a metrics table is present."""

    def __init__(self, html: str):
        super().__init__()
        self.images: list[dict[str, str]] = []
        self.table = False
        self.feed(html)

    def handle_starttag(self, tag, attrs):
        self.images += [dict(attrs)] if tag == "img" else []
        self.table |= tag == "table" and ("class", "metrics") in attrs


def chromium_dom(page: Path, tmp_path: Path) -> str:
    """The DOM of a page after load in headless Chromium, with each img's naturalWidth written into it."""
    probe = page.with_name("probe.html")
    probe.write_text(page.read_text().replace("</body>", PROBE + "\n</body>"))
    cmd = [shutil.which("chromium"), "--headless", "--no-sandbox", "--disable-gpu", f"--user-data-dir={tmp_path}",
           "--virtual-time-budget=5000", "--dump-dom", probe.as_uri()]
    try:
        return subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=True).stdout
    finally:
        probe.unlink()


@pytest.mark.skipif(shutil.which("chromium") is None,
                    reason="headless Chromium is not installed (Debian `chromium`; scripts/setup.sh installs it)")
def test_every_image_of_the_report_loads_in_chromium(results, tmp_path):
    page = results.report_html
    build_report(results, page, results.report_figures)
    written = Images(page.read_text())
    assert written.table
    alts = {img["alt"] for img in written.images}
    assert {"quality vs diversity", "roughness vs diversity"} <= alts
    for scene in ROUGHNESS:
        assert {f"{scene} {what}" for what in ("input views", "env maps", "uncertainty", "textures",
                                                     "held-out views", "relit views")} <= alts
    assert all(not img["src"].startswith(("/", "file:", "http")) for img in written.images)
    first = next(iter(ROUGHNESS))
    assert f"{first} masks" in alts and not any(f"{scene} masks" in alts for scene in list(ROUGHNESS)[1:])
    flagged = read_capture_json(results.scene(first).capture_json).views[1].name
    assert "derived masks of 1 of" in page.read_text() and f"unreliable ({flagged}: 50% of the object&#x27;s points fall outside)" in page.read_text()

    loaded = Images(chromium_dom(page, tmp_path))
    assert loaded.table and len(loaded.images) == len(written.images)
    assert all(int(img.get("data-natural-width", 0)) > 0 for img in loaded.images), loaded.images


def test_table_marks_the_best_value_per_scene_and_greys_missing_ones():
    table = metric_table(summary_rows())
    lines = table.splitlines()
    glossy_dps, rough_init = lines[5], lines[6]
    assert lines[3].startswith('<tr class="scene-start">') and rough_init.startswith('<tr class="scene-start">')
    # dps: the best held-out PSNR (22), albedo MSE (0.01) and naturalness of its scene; its LPIPS is missing.
    assert glossy_dps.count('class="best"') == 3 and "22" in glossy_dps and "0.01" in glossy_dps
    assert '<td class="missing" title="no LPIPS weights">missing</td>' in glossy_dps
    assert "&plusmn; 0.5" in glossy_dps
    assert table.count('class="best"') == 2 * 4  # psnr, lpips, mse, naturalness per scene; sigma2 never


@pytest.mark.parametrize("column, expected", [("novel_psnr", 1), ("env_ssim", 1), ("env_naturalness", 1),
                                              ("novel_lpips", -1), ("env_fid", -1), ("env_niqe", -1),
                                              ("albedo_mse", -1), ("albedo_sigma2_invar", -1),
                                              ("env_sigma2_sample", 0), ("sample_seconds", 0), ("samples", 0)])
def test_direction_of_each_metric(column, expected):
    assert direction(column) == expected


def test_without_naturalness_or_sweep_the_page_says_so(results, tmp_path):
    page = Page(tmp_path / "report.html", tmp_path / "report")
    quality = quality_section(summary_rows(naturalness=False), page)
    assert "Marker size is constant: summary.csv has no env_naturalness column" in quality
    one_scene = [r for r in summary_rows() if r["scene"] == "glossy"]
    capture = read_capture_json(results.scene("glossy").capture_json)
    assert "no roughness sweep" in roughness_section(one_scene, {"glossy": capture}, page)
