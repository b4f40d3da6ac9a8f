"""The export: a glTF binary and a USD stage per scene, every sample a variant. Checked by the formats' own
tools (the Khronos glTF validator, USD's validators), read back and compared with the EXRs, the texture
convention against the renderer's, and the report's 3D view rendered in headless Chromium."""

from __future__ import annotations

import json
import shutil
import subprocess
from dataclasses import replace
from pathlib import Path

import numpy as np
import pygltflib
import pytest
from PIL import Image

from dpi.export.asset import png_bytes, renderer_mesh
from dpi.io.exr import read_exr
from dpi.io.images import linear_to_srgb
from dpi.stages import capture_stage, export_stage, init_stage, sample_stage, uncertainty_stage
from stage_jobs import stage_job

REPO = Path(__file__).resolve().parent.parent
VALIDATOR = REPO / "node_modules" / "gltf-validator"
SAMPLES = {"none": 2, "smoothness": 1}


@pytest.fixture(scope="module")
def exported(tiny_capture, tmp_path_factory):
    """The tiny capture's init, two `none` samples and a `smoothness` one, their spread maps, and the export."""
    job = stage_job(tiny_capture, tmp_path_factory.mktemp("export") / "results", render={"spp": 4},
                    problem={"env_height": 8, "texture_size": 8}, init={"iterations": 3},
                    method_params={m: {"iterations": 2} for m in SAMPLES})
    capture_stage(job)
    init_stage(job)
    rows = []
    for method, n in SAMPLES.items():
        for k in range(n):
            sample_stage(replace(job, method=method, k=k))
        rows.append((method, [job.paths.sample_dir(method, k) for k in range(n)]))
    uncertainty_stage(job, rows[:1])
    export_stage(job, rows)
    return job


def glb(job) -> pygltflib.GLTF2:
    return pygltflib.GLTF2().load_binary(str(job.paths.export_asset("glb")))


def image_of(gltf: pygltflib.GLTF2, texture: int) -> np.ndarray:
    view = gltf.bufferViews[gltf.images[gltf.textures[texture].source].bufferView]
    data = gltf.binary_blob()[view.byteOffset:view.byteOffset + view.byteLength]
    import io

    return np.asarray(Image.open(io.BytesIO(data)))


def test_every_sample_is_a_variant_the_first_the_default(exported):
    gltf = glb(exported)
    names = [v["name"] for v in gltf.extensions["KHR_materials_variants"]["variants"]]
    assert names == ["none 0", "none 1", "smoothness 0", "init"]
    primitive = gltf.meshes[0].primitives[0]
    mappings = primitive.extensions["KHR_materials_variants"]["mappings"]
    assert [gltf.materials[m["material"]].name for m in mappings] == names and primitive.material == 0
    extras = gltf.materials[0].extras["dpi"]
    assert (exported.paths.export_dir / extras["envmap_hdr"]).is_file() and "spread_textures" in extras
    assert (exported.paths.export_dir / extras["envmap_exr"]).is_file()


def test_textures_round_trip_within_8_bits(exported):
    """Base colour = sRGB of the albedo EXR, roughness in green and metallic in blue, to within quantisation."""
    gltf = glb(exported)
    for material in gltf.materials:
        folder = exported.paths.sample_dir(*(material.name.split(" ") if " " in material.name else (material.name,)))
        pbr = material.pbrMetallicRoughness
        base = image_of(gltf, pbr.baseColorTexture.index).astype(float) / 255
        albedo = linear_to_srgb(read_exr(folder / "albedo.exr")[..., :3])
        np.testing.assert_allclose(base, albedo, atol=0.5 / 255 + 1e-6)
        packed = image_of(gltf, pbr.metallicRoughnessTexture.index).astype(float) / 255
        np.testing.assert_allclose(packed[..., 1], np.clip(read_exr(folder / "roughness.exr")[..., 0], 0, 1),
                                   atol=0.5 / 255 + 1e-6)
        np.testing.assert_allclose(packed[..., 2], np.clip(read_exr(folder / "metallic.exr")[..., 0], 0, 1),
                                   atol=0.5 / 255 + 1e-6)


def test_the_mesh_is_the_renderers_and_a_texel_reads_as_the_renderer_reads_it(exported, mi):
    """glTF samples texel (row v H, column u W) at uv (u, v); so does the renderer's bitmap texture (row 0 at
    v = 0), so the exported textures need no flip."""
    from dpi.capture import complete_capture, read_capture_json
    from dpi.render.renderer import texture_plugin

    gltf = glb(exported)
    capture = complete_capture(read_capture_json(exported.paths.capture_json), exported.paths)
    mesh = renderer_mesh(capture.mesh)
    accessor = gltf.accessors[gltf.meshes[0].primitives[0].attributes.TEXCOORD_0]
    view = gltf.bufferViews[accessor.bufferView]
    uvs = np.frombuffer(gltf.binary_blob()[view.byteOffset:view.byteOffset + view.byteLength], np.float32)
    np.testing.assert_array_equal(uvs.reshape(-1, 2), mesh.uvs)
    ramp = np.zeros((4, 4, 3), np.float32)
    ramp[..., 0] = np.arange(4)[:, None] / 3  # red counts rows
    ramp[..., 1] = np.arange(4)[None, :] / 3  # green counts columns
    texture = mi.load_dict(texture_plugin(ramp))
    si = mi.SurfaceInteraction3f()
    si.uv = mi.Point2f(0.125, 0.875)  # the centre of row 3, column 0 in glTF's convention
    value = np.asarray(texture.eval(si)).ravel()
    np.testing.assert_allclose(value[:2], [ramp[3, 0, 0], ramp[3, 0, 1]], atol=1e-6)


@pytest.mark.skipif(shutil.which("node") is None or not VALIDATOR.is_dir(),
                    reason="the Khronos glTF validator is not installed (Node.js and `npm ci`: scripts/setup.sh)")
def test_the_asset_passes_the_khronos_gltf_validator(exported, tmp_path):
    script = tmp_path / "validate.js"
    script.write_text("const v = require('gltf-validator'); const fs = require('fs');\n"
                      "v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2])))"
                      ".then((r) => console.log(JSON.stringify(r.issues)));\n")
    out = subprocess.run(["node", str(script), str(exported.paths.export_asset("glb"))], capture_output=True,
                         text=True, check=True, timeout=120, env={"NODE_PATH": str(REPO / "node_modules")})
    issues = json.loads(out.stdout)
    assert issues["numErrors"] == 0, issues["messages"]


def test_the_usd_stage_passes_usds_validators_and_switches_by_variant(exported):
    from pxr import Usd, UsdShade, UsdValidation

    stage = Usd.Stage.Open(str(exported.paths.export_asset("usda")))
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    errors = UsdValidation.ValidationContext(validators).Validate(stage)
    assert [e.GetMessage() for e in errors] == []
    variants = stage.GetDefaultPrim().GetVariantSets().GetVariantSet("sample")
    assert variants.GetVariantNames() == ["init", "none_0", "none_1", "smoothness_0"]
    assert variants.GetVariantSelection() == "none_0"
    seen = set()
    for name in variants.GetVariantNames():
        variants.SetVariantSelection(name)
        material = UsdShade.MaterialBindingAPI(stage.GetPrimAtPath("/asset/object")).ComputeBoundMaterial()[0]
        light = stage.GetPrimAtPath("/asset/light").GetAttribute("inputs:texture:file").Get().path
        assert material.GetPath().name == name and light == f"envmaps/{name}.exr"
        assert (exported.paths.export_dir / light).is_file()
        seen.add(light)
    assert len(seen) == 4


@pytest.mark.skipif(shutil.which("chromium") is None or not (REPO / "node_modules" / "@google").is_dir(),
                    reason="headless Chromium and model-viewer are not installed (scripts/setup.sh)")
def test_the_reports_3d_view_renders_and_follows_the_sample(exported, tmp_path):
    """The 3D view of the report in headless Chromium (software WebGL): a picture of the object, and another
    when another sample is chosen."""
    from dpi.evaluation.view3d import SCRIPT_NAME, install_viewer, view3d_section

    section = "\n".join(view3d_section("tiny", exported.paths, install_viewer(tmp_path / "report") is not None, 1.0))
    page = tmp_path / "view.html"
    page.write_text(f"<!DOCTYPE html><html><head><script src='report/{SCRIPT_NAME}'></script><style>"
                    "body { margin: 0; } body > :not(model-viewer):not(script) { display: none; } "
                    "model-viewer { width: 320px !important; height: 240px !important; }</style></head><body>"
                    + section + "</body></html>")
    shots = {}
    for sample in ("none 0", "smoothness 0"):
        shot = tmp_path / f"{sample.replace(' ', '_')}.png"
        subprocess.run([shutil.which("chromium"), "--headless", "--no-sandbox", f"--user-data-dir={tmp_path / 'c'}",
                        "--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--window-size=320,240",
                        "--virtual-time-budget=20000", f"--screenshot={shot}",
                        f"{page.as_uri()}?sample={sample.replace(' ', '%20')}"],
                       capture_output=True, timeout=180, check=True)
        shots[sample] = np.asarray(Image.open(shot).convert("RGB"), dtype=float)
    background = np.array([0x33, 0x33, 0x33], float)
    for picture in shots.values():
        assert (np.abs(picture - background).sum(-1) > 30).mean() > 0.05  # the object covers part of the view
    assert np.abs(shots["none 0"] - shots["smoothness 0"]).mean() > 0.5  # another sample, another picture


def test_png_bytes_takes_one_channel_images():
    assert Image.open(__import__("io").BytesIO(png_bytes(np.zeros((4, 4, 1), np.uint8)))).mode == "L"


def sample_rows(job) -> list[tuple[str, list[Path]]]:
    return [(method, [job.paths.sample_dir(method, k) for k in range(n)]) for method, n in SAMPLES.items()]


def test_an_export_folder_that_links_outside_results_is_refused_and_nothing_written_there(exported, tmp_path):
    from dpi.io.atomic import OutputError

    outside = tmp_path / "elsewhere"
    outside.mkdir()
    folder = exported.paths.export_dir
    kept = folder.with_name("export_kept")
    folder.rename(kept)
    try:
        folder.symlink_to(outside, target_is_directory=True)
        with pytest.raises(OutputError, match="is a link"):
            export_stage(exported, sample_rows(exported))
        assert list(outside.iterdir()) == []
    finally:
        folder.unlink(missing_ok=True)
        kept.rename(folder)


def test_a_failed_export_leaves_the_previous_folder_whole_and_no_stray_files(exported, monkeypatch):
    import dpi.stages.export as stage

    folder = exported.paths.export_dir
    before = sorted(p.relative_to(folder) for p in folder.rglob("*"))
    (folder / "stale.txt").write_text("from an older export")

    def broken(*args, **kwargs):
        raise RuntimeError("USD writer failed")

    monkeypatch.setattr(stage, "write_usd", broken)
    with pytest.raises(RuntimeError, match="USD writer failed"):
        export_stage(exported, sample_rows(exported))
    assert sorted(p.name for p in folder.parent.iterdir() if p.name.startswith(".export")) == []
    assert (folder / "stale.txt").is_file()
    monkeypatch.undo()
    export_stage(exported, sample_rows(exported))  # a whole export replaces the folder: the stale file goes
    assert sorted(p.relative_to(folder) for p in folder.rglob("*")) == before


@pytest.mark.parametrize("shapes, bad", [
    ({"albedo": (7, 5, 3), "roughness": (8, 8, 1), "metallic": (8, 8, 1)}, "albedo"),
    ({"albedo": (8, 8, 3), "roughness": (16, 16, 1), "metallic": (8, 8, 1)}, "roughness"),
])
def test_a_sample_texture_of_the_wrong_size_is_refused_naming_it(tmp_path, shapes, bad):
    from dpi.export.asset import AssetMesh, AssetSample, sample_textures
    from dpi.io.exr import write_exr
    from dpi.io.layout import decomposition_files

    files = decomposition_files(tmp_path)
    for name, shape in shapes.items():
        write_exr(files[name], np.full(shape, 0.5, np.float32))
    mesh = AssetMesh(np.eye(3, dtype=np.float32), np.eye(3, dtype=np.float32),
                     np.array([[0, 0], [1, 0], [0, 1]], np.float32), np.array([[0, 1, 2]], np.uint32))
    with pytest.raises(ValueError, match=rf"{files[bad].name}: texture is \d+x\d+ px; a sample's textures are square"):
        sample_textures(AssetSample("dps", 0, tmp_path), mesh)
