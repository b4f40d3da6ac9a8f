"""Stage of rules/export.smk: a scene's decompositions as one glTF binary and one USD stage, every sample a variant,
with each sample's env map beside them (.hdr and .exr) and the USD stage's textures."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Callable

import numpy as np

from dpi.capture import complete_capture, read_capture_json
from dpi.export.asset import AssetMesh, AssetSample, png_bytes, renderer_mesh, sample_textures, unit_to_uint8
from dpi.export.gltf import write_glb
from dpi.export.usd import write_usd
from dpi.io.atomic import atomic_path, replaced_folder
from dpi.io.exr import read_exr
from dpi.io.images import write_hdr
from dpi.io.layout import INIT, SceneLayout
from dpi.stages.job import StageJob

SPREAD_NOTE = ("spread_textures: per method with 2 or more samples, its samples' per-texel albedo std "
               "(albedo_std, RGB) and env log-luminance std (env_log_std, equirectangular), stored as 8-bit "
               "value / scale with the scale in spread_scales; exact values: results/{scene}/{method}/*.exr. "
               "Env maps: envmaps/{method}_{k}.hdr and .exr beside this file, equirectangular, +Y up as dpi "
               "renders them.")


def asset_samples(job: StageJob, rows: list[tuple[str, list[str | Path]]]) -> list[AssetSample]:
    """Every sample of `rows` (method, its sample folders) and the init, the first dps sample first."""
    samples = [AssetSample(method, k, Path(folder)) for method, folders in rows for k, folder in enumerate(folders)]
    samples.sort(key=lambda s: s.method != "dps")
    return samples + [AssetSample(INIT, None, job.paths.sample_dir(INIT))]


def _write_png(path: Path, pixels: np.ndarray) -> str:
    with atomic_path(path) as tmp:
        tmp.write_bytes(png_bytes(pixels))
    return path.name


def _spread(job: StageJob, methods: set[str]) -> tuple[dict[str, dict[str, np.ndarray]], dict[str, dict[str, float]]]:
    """Per method with spread maps: their 8-bit encodings and scales."""
    maps, scales = {}, {}
    for method in sorted(methods):
        files = job.paths.uncertainty(method)
        if not files["albedo"].is_file():
            continue
        values = {"albedo_std": read_exr(files["albedo"])[..., :3], "env_log_std": read_exr(files["env"])[..., :3]}
        scales[method] = {name: max(float(v.max()), 1e-6) for name, v in values.items()}
        maps[method] = {name: unit_to_uint8(v / scales[method][name]) for name, v in values.items()}
    return maps, scales


def export_stage(job: StageJob, rows: list[tuple[str, list[str | Path]]]) -> None:
    """The scene's .glb and .usda under its export folder, from the samples of `rows` and the init: written in a
    temporary folder that replaces the export folder whole (dpi.io.atomic.replaced_folder: inside results_dir, never
    through a link)."""
    paths = job.paths
    capture = complete_capture(read_capture_json(paths.capture_json), paths)
    mesh = renderer_mesh(capture.mesh)
    samples = asset_samples(job, rows)
    with replaced_folder(paths.export_dir, job.pipeline.layout.results) as folder:
        write_export(paths, mesh, samples, job, lambda path: folder / path.relative_to(paths.export_dir))
    print(f"export: {len(samples)} samples as variants: {paths.export_asset('glb')}, {paths.export_asset('usda')}",
          flush=True)


def write_export(paths: SceneLayout, mesh: AssetMesh, samples: list[AssetSample], job: StageJob,
                 staged: Callable[[Path], Path]) -> None:
    """The export folder's files, each at `staged`(its final path)."""
    textures, envmaps, extras = {}, {}, {}
    for sample in samples:
        env = read_exr(sample.files["env"])[..., :3]
        exr, hdr = paths.export_envmap(sample.label, "exr"), paths.export_envmap(sample.label, "hdr")
        staged(exr).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(sample.files["env"], staged(exr))
        write_hdr(staged(hdr), env)
        encoded = sample_textures(sample, mesh)
        textures[sample.name] = {
            texture: f"textures/{_write_png(staged(paths.export_texture(sample.label, texture)), encoded[key])}"
            for texture, key in (("albedo", "base_color"), ("roughness", "roughness"), ("metallic", "metallic"))}
        envmaps[sample.name] = f"envmaps/{exr.name}"
        extras[sample.name] = {"envmap_hdr": f"envmaps/{hdr.name}", "envmap_exr": f"envmaps/{exr.name}"}
    spread, scales = _spread(job, {s.method for s in samples})
    for sample in samples:
        if sample.method in scales:
            extras[sample.name]["spread_scales"] = scales[sample.method]
    write_glb(staged(paths.export_asset("glb")), mesh, samples, extras, spread, SPREAD_NOTE)
    write_usd(staged(paths.export_asset("usda")), mesh, samples, textures, envmaps)
