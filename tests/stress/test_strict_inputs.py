"""Inputs read as what they are, with known answers: numeric strings only where nerfstudio takes them,
camera.xml properties of Mitsuba's types, masks saved with an opaque alpha read by their grey value,
mesh.PLY found, captures that cannot be scored or constrain little warned about in the log and the
report, and the workflow's capture rule printing the one line `dpi validate` prints."""

from __future__ import annotations

import json
import runpy
import shutil
import subprocess
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from capture_helpers import NAMES, SIZE, cameras, edit_transforms, make_capture, sphere_mask
from PIL import Image
from workflow_helpers import REPO, SNAKEMAKE, write_config

from dpi.capture import CaptureError, CaptureWarning, inspect_capture, load_capture
from dpi.io.images import read_mask
from dpi.preprocess.derive import normalise_capture


def test_numeric_strings_are_numbers_where_nerfstudio_reads_them(tmp_path):
    """"w": "8", "fl_x": "10.99" and a NeRF-synthetic "camera_angle_x": "0.698" read as the numbers."""
    root = make_capture(tmp_path / "scene")

    def stringify(data: dict) -> None:
        for frame in data["frames"]:
            frame["w"], frame["fl_x"] = "8", str(frame["fl_x"])
    edit_transforms(root, stringify)
    capture = load_capture(root)
    assert capture.views[0].camera.width == SIZE and capture.views[0].camera.fov_x_deg == pytest.approx(40.0)


def sensors_xml(fov: str = '<float name="fov" value="40"/>', width: str = f'<integer name="width" value="{SIZE}"/>') -> str:
    """camera.xml of the helper's cameras as look-at sensors, with the given fov and film-width elements."""
    sensors = "".join(
        f'<sensor type="perspective" id="cam{i}">{fov}<transform name="to_world"><lookat origin="{c.center[0]}, '
        f'{c.center[1]}, {c.center[2]}" target="0, 0, 0" up="0, 1, 0"/></transform><film type="hdrfilm">{width}'
        f'<integer name="height" value="{SIZE}"/></film></sensor>' for i, c in enumerate(cameras()))
    return f'<scene version="3.0.0">{sensors}</scene>'


XML_CASES = {  # case: (sensors_xml arguments, the message after the file, or None: valid)
    "valid": ({}, None),
    "integer fov": ({"fov": '<integer name="fov" value="40"/>'}, None),
    "fov as string": ({"fov": '<string name="fov" value="40"/>'},
                      "sensor 'cam0': fov must be a float (<float>), got <string name=\"fov\" value=\"40\"/>"),
    "fov not a number": ({"fov": '<float name="fov" value="wide"/>'},
                         "sensor 'cam0': fov must be a float, got <float name=\"fov\" value=\"wide\"/>"),
    "fov boolean": ({"fov": '<boolean name="fov" value="true"/>'},
                    "sensor 'cam0': fov must be a float (<float>), got <boolean name=\"fov\" value=\"true\"/>"),
    "fractional width": ({"width": '<integer name="width" value="8.5"/>'},
                         "sensor 'cam0' film: width must be an integer, got <integer name=\"width\" value=\"8.5\"/>"),
    "width as float": ({"width": '<float name="width" value="8"/>'},
                       "sensor 'cam0' film: width must be an integer (<integer>), got <float"),
}


@pytest.mark.parametrize("case", list(XML_CASES))
def test_camera_xml_properties_have_mitsubas_types(tmp_path, case):
    """A property of the wrong tag or an unreadable value is named with its sensor; Mitsuba's own leniency
    (an <integer> fov) is kept."""
    kwargs, words = XML_CASES[case]
    root = make_capture(tmp_path / "scene", transforms=False)
    (root / "camera.xml").write_text(sensors_xml(**kwargs))
    if words is None:
        assert load_capture(root).views[0].camera.fov_x_deg == pytest.approx(40.0)
        return
    with pytest.raises(CaptureError) as info:
        load_capture(root)
    assert str(info.value).startswith(f"{root / 'camera.xml'}: {words}"), str(info.value)


def rgba_masks(root: Path, alpha) -> None:
    """Rewrite the masks as RGBA PNGs: grey = the sphere's disc, alpha as given (per pixel, or 255)."""
    for name in NAMES:
        grey = np.where(sphere_mask(), 255, 0).astype(np.uint8)
        rgba = np.dstack([grey, grey, grey, np.broadcast_to(alpha, grey.shape).astype(np.uint8)])
        Image.fromarray(rgba, "RGBA").save(root / "masks" / f"{name}.png")


def test_rgba_mask_with_an_opaque_alpha_reads_as_its_grey_value(tmp_path):
    """What many editors save: a black-and-white mask with alpha 255 everywhere (was 100% foreground)."""
    root = make_capture(tmp_path / "scene")
    rgba_masks(root, 255)
    capture = load_capture(root)
    np.testing.assert_array_equal(read_mask(capture.views[0].mask), sphere_mask())


def test_rgba_mask_whose_alpha_varies_reads_its_alpha(tmp_path):
    """A cut-out: white everywhere, the object in the alpha channel."""
    path = tmp_path / "m.png"
    alpha = np.where(sphere_mask(), 255, 0).astype(np.uint8)
    Image.fromarray(np.dstack([np.full((SIZE, SIZE, 3), 255, np.uint8), alpha]), "RGBA").save(path)
    np.testing.assert_array_equal(read_mask(path), sphere_mask())


def test_mesh_file_names_ignore_case(tmp_path):
    """mesh.PLY is the capture's mesh (was ignored, and a mesh derived); with mesh.ply beside it, ambiguous."""
    root = make_capture(tmp_path / "scene")
    (root / "mesh.ply").rename(root / "mesh.PLY")
    assert inspect_capture(root)["mesh"] and load_capture(root).mesh.name == "mesh.PLY"
    shutil.copy(root / "mesh.PLY", root / "mesh.ply")
    with pytest.raises(CaptureError, match=r"mesh\.ply: ambiguous mesh, mesh\.PLY is also given"):
        load_capture(root)


def test_ground_truth_in_the_authors_layout_passes(tmp_path):
    """An envmap with a wrap column (H x 2H+1) validates, as the evaluation reads it."""
    from dpi.io.exr import write_exr

    root = make_capture(tmp_path / "scene")
    env = np.random.default_rng(0).uniform(0.5, 2.0, (4, 8, 3)).astype(np.float32)
    write_exr(root / "gt" / "envmap.exr", np.concatenate([env, env[:, :1]], axis=1))
    assert load_capture(root).gt["envmap"].name == "envmap.exr"


WARNED = {  # case: (scene.yaml, the warning)
    "nothing held out": ("held_out: []\n", "no held-out view, so the novel-view metrics (PSNR, SSIM, LPIPS) cannot be "
                                          "scored"),
    "two training views": ("held_out: [r_2, r_3]\n", "only 2 training view(s): too few to constrain the illumination"),
}


@pytest.mark.parametrize("case", list(WARNED))
def test_weak_captures_are_warned_about(tmp_path, case):
    """Usable, with a warning starting with the capture folder."""
    text, words = WARNED[case]
    root = make_capture(tmp_path / "scene")
    (root / "scene.yaml").write_text(text)
    with pytest.warns(CaptureWarning) as caught:
        load_capture(root)
    assert any(str(w.message) == f"{root}: {words}" or str(w.message).startswith(f"{root}: {words}")
               for w in caught), [str(w.message) for w in caught]


def test_the_report_shows_a_capture_warning(tiny_capture, tmp_path):
    """A scene without held-out views: its section of the report opens with the warning."""
    from dpi.evaluation.report import Page, scene_section
    from dpi.io.layout import Layout

    layout = Layout(tmp_path / "results", tmp_path / "captures")
    root = shutil.copytree(tiny_capture, layout.capture_dir("mine"))
    with open(root / "scene.yaml", "a") as f:
        f.write("held_out: []\n")
    scene = layout.scene("mine")
    with pytest.warns(CaptureWarning):
        normalise_capture(root, scene.capture_json)
    scene.evaluation("none", 0).parent.mkdir(parents=True)
    scene.evaluation("none", 0).write_text(json.dumps({"exposure": 1.0, "metrics": {}}))
    scene.envmap_figure.parent.mkdir(parents=True, exist_ok=True)
    Image.new("RGB", (4, 4)).save(scene.envmap_figure)
    html = scene_section("mine", scene, [{"scene": "mine", "method": "none"}], Page(tmp_path / "r.html", tmp_path / "r"))
    assert "<p class='warning'><b>Warning:</b> " in html and "no held-out view" in html


def truncated_capture(root: Path) -> tuple[Path, str]:
    """The helper capture with a truncated EXR, and the line `dpi validate` stops it with."""
    make_capture(root)
    data = (root / "images" / "r_2.exr").read_bytes()
    (root / "images" / "r_2.exr").write_bytes(data[: len(data) // 2])
    with pytest.raises(CaptureError) as info:
        load_capture(root)
    return root, str(info.value)


def test_the_capture_script_ends_with_the_one_line(tmp_path):
    """The capture rule's script (workflow_scripts/stage.py) run as Snakemake's `script:` runs it: exit status 1 with
    the line as the only output (SystemExit prints it on stderr) and in the log, no traceback and no capture.json."""
    from dpi.stages import resolve_config

    root, line = truncated_capture(tmp_path / "captures" / "mine")
    log, out = tmp_path / "capture.log", tmp_path / "results" / "mine" / "capture.json"
    config = resolve_config({"captures_dir": str(root.parent), "results_dir": str(tmp_path / "results"),
                             "scenes": ["mine"]})
    snakemake = SimpleNamespace(log=[str(log)], rule="capture", config=config, threads=1,
                                wildcards=SimpleNamespace(scene="mine"), params={})
    with pytest.raises(SystemExit) as info:
        runpy.run_path(str(REPO / "workflow_scripts" / "stage.py"), init_globals={"snakemake": snakemake})
    assert info.value.code == line and log.read_text() == line + "\n" and not out.exists()


@pytest.mark.slow
def test_the_workflow_prints_the_one_line_of_a_bad_capture(tmp_path):
    """The same through Snakemake (10 s): the line in its output and the job's log, no traceback (were four chained
    ones under "message: None")."""
    _, line = truncated_capture(tmp_path / "captures" / "mine")
    write_config(tmp_path / "config.yaml", {"scenes": ["mine"], "methods": ["none"]})
    proc = subprocess.run([str(SNAKEMAKE), "-s", str(REPO / "Snakefile"), "--directory", str(tmp_path), "--configfile",
                           str(tmp_path / "config.yaml"), "--cores", "1", "results/mine/capture.json"],
                          capture_output=True, text=True, timeout=300)
    output = proc.stdout + proc.stderr
    assert proc.returncode != 0 and "Traceback" not in output and f"\n{line}\n" in output, output[-3000:]
    assert (tmp_path / "results" / "mine" / "logs" / "capture.log").read_text() == line + "\n"
