"""The report's 3D view of a scene: its exported glTF asset in model-viewer, lit by the chosen sample's env map,
with a selector over the samples (the asset's KHR_materials_variants). Offline: the asset and the env maps are
embedded in the page as data URIs (a page opened from disk may not fetch files), and model-viewer's script is
copied next to the page from the checkout's node_modules (scripts/setup.sh installs it) or `$DPI_MODEL_VIEWER`."""

from __future__ import annotations

import base64
import json
import os
import shutil
from html import escape
from pathlib import Path

import numpy as np

from dpi.io.layout import SceneLayout

MODEL_VIEWER = Path(__file__).resolve().parents[2] / "node_modules" / "@google" / "model-viewer" / "dist" / \
    "model-viewer-umd.min.js"
"""model-viewer's classic-script build in the checkout (a module script would not load from disk)"""
SCRIPT_NAME = "model-viewer.min.js"
MIN_ROWS = 64
"""a map is shown at least this tall (texels repeated): model-viewer's prefiltering turns a smaller map black"""


def model_viewer_script() -> Path | None:
    """model-viewer's script: `$DPI_MODEL_VIEWER`, else the checkout's node_modules; None when neither exists."""
    path = Path(os.environ.get("DPI_MODEL_VIEWER", MODEL_VIEWER))
    return path if path.is_file() else None


def install_viewer(figures: Path) -> Path | None:
    """Copy model-viewer's script into the report's figures folder, once a report; its copy, or None when it is
    not installed."""
    script = model_viewer_script()
    if script is None:
        return None
    figures.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(script, figures / SCRIPT_NAME)
    return figures / SCRIPT_NAME


def data_uri(data: bytes, mime: str) -> str:
    return f"data:{mime};base64,{base64.b64encode(data).decode()}"


def display_hdr(path: Path) -> bytes:
    """A Radiance .hdr map as the view shows it: its texels repeated up to MIN_ROWS rows."""
    from dpi.io.images import hdr_bytes, read_hdr

    env = read_hdr(path)
    repeat = -(-MIN_ROWS // env.shape[0])
    return hdr_bytes(np.repeat(np.repeat(env, repeat, 0), repeat, 1))


def asset_variants(glb: bytes) -> list[tuple[str, str]]:
    """(variant name, its env map's .hdr path relative to the asset) of an exported asset, in the asset's order."""
    import pygltflib

    from dpi.export.gltf import VARIANTS

    gltf = pygltflib.GLTF2.load_from_bytes(glb)
    names = [v["name"] for v in gltf.extensions[VARIANTS]["variants"]]
    hdr = {m.name: m.extras["dpi"]["envmap_hdr"] for m in gltf.materials}
    return [(name, hdr[name]) for name in names]


def view3d_section(scene_name: str, scene: SceneLayout, viewer: bool, exposure: float) -> list[str]:
    """The scene's 3D view (HTML), or a note saying why there is none. `viewer`: model-viewer's script is on the
    page (`install_viewer`); `exposure` is the capture's (the view divides radiance by it, as the other figures
    do)."""
    glb = scene.export_asset("glb")
    if not glb.is_file() or not viewer:
        why = ("no exported asset (rule export)" if not glb.is_file()
               else "model-viewer is not installed (scripts/setup.sh)")
        return [f"<p class='note'>No 3D view: {why}.</p>"]
    asset = glb.read_bytes()
    variants = asset_variants(asset)
    # model-viewer reads a map as HDR when its URL ends in .hdr: a fragment says so without changing the data
    envs = {name: data_uri(display_hdr(glb.parent / hdr), "image/vnd.radiance") + "#.hdr" for name, hdr in variants}
    element = f"view3d-{scene_name}"
    options = "".join(f"<option value='{escape(n)}'>{escape(n)}</option>" for n, _ in variants)
    first = variants[0][0]
    return [
        f"<h3>{escape(scene_name)}: 3D view</h3>",
        f"<p class='note'>The exported asset ({escape(glb.name)}: every sample a variant) lit by the chosen sample's "
        "env map; drag to turn it. The same file opens in Blender (File &gt; Import &gt; glTF) and on the web.</p>",
        f"<label>sample <select id='{element}-select'>{options}</select></label>",
        f"<model-viewer id='{element}' class='view3d' src='{data_uri(asset, 'model/gltf-binary')}' "
        f"environment-image='{envs[first]}' variant-name='{escape(first)}' exposure='{1.0 / exposure:.6g}' "
        "camera-controls interaction-prompt='none' shadow-intensity='0' "
        "style='width: 480px; height: 360px; background: #333;'></model-viewer>",
        "<script>(function () {",
        f"  const view = document.getElementById({json.dumps(element)});",
        f"  const select = document.getElementById({json.dumps(element + '-select')});",
        f"  const envs = {json.dumps(envs)};",
        "  function show(name) { view.variantName = name; view.environmentImage = envs[name]; select.value = name; }",
        "  select.addEventListener('change', (event) => show(event.target.value));",
        "  const wanted = new URLSearchParams(location.search).get('sample');",
        "  if (wanted && wanted in envs) show(wanted);",
        "})();</script>",
    ]
