"""Synthetic captures with ground truth: procedural mesh, textures and sky, rendered by Mitsuba.

Writes a capture folder in dpi's input layout: images/ (linear EXR or sRGB PNG, the other format
in preview/), masks/, transforms.json (held-out views flagged), mesh.ply with UVs (or a scanner-like one without, and
the true one in gt/: SynthConfig.scan_faces), gt/ and
scene.yaml. The folder is built next to its destination and renamed into place, and a
`.synth.json` marker (the parameters) is written last, so a killed run leaves no capture behind.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from dataclasses import asdict
from pathlib import Path
from typing import Annotated

import numpy as np
import torch
import yaml
from pydantic import Field
from tqdm import tqdm

from dpi.capture.cameras import from_fov, orbit, write_transforms
from dpi.io.atomic import write_json, write_text
from dpi.io.exr import write_exr
from dpi.io.images import luminance, write_mask, write_srgb, write_srgb_alpha
from dpi.io.layout import SYNTH_MARKER
from dpi.io.meshes import write_mesh_ply
from dpi.io.settings import (Count, Elevation, Fraction, ImageSize, Loose, MapHeight, Rate, SamplesPerPixel, Steps,
                          TextureSize, Weight, settings, settings_from_dict)
from dpi.prior.data import read_panorama, resize_map
from dpi.render.renderer import RenderConfig, Renderer
from dpi.synth.backdrop import BACKGROUNDS, add_detail, composite_backdrop
from dpi.solve.seams import SeamTies
from dpi.synth.shapes import BASE_V, BODY_V, make_shape, write_ply
from dpi.synth.textures import procedural_materials
from dpi.worlds.families import generator
from dpi.worlds.skies import SkyParams, sunsky_envmap

EVALUATION_SEED_STREAM = 7_919  # ground-truth maps draw from default_rng([this, seed]); datasets from [seed, chunk], seed 0


FOV_DEG = 35.0
BASED_SHAPES = ("blob_on_plate",)
"""shapes with a base that carries the second material (SynthConfig.base_roughness, base_metallic)"""
BASE_ALBEDO = 0.8
"""the base's albedo (a metal's specular colour): a light grey"""
PROCEDURAL = ("sunsky", "outdoor", "indoor")
"""the ground-truth lights SynthConfig.environment names; anything else is a panorama file"""
PANORAMA_SUFFIXES = (".exr", ".hdr")
LAYOUTS = ("dpi", "nerf_synthetic")
"""how a synthetic capture is laid out (SynthConfig.layout)"""


@settings
class SynthConfig:
    """Parameters of one synthetic capture."""

    shape: str = "blob"
    """procedural mesh: blob or bumpy_torus"""
    views: Count = 16
    """number of rendered views (training + held-out)"""
    held_out_every: Steps = 4
    """every n-th view is held out for novel-view evaluation (0: none)"""
    width: ImageSize = 64
    height: ImageSize = 64
    camera_distance: Rate = 4.0
    elevations_deg: Annotated[tuple[Elevation, ...], Loose] = (10.0, 35.0)
    arc_deg: Annotated[float, Field(gt=0, le=360)] = 360.0
    """azimuth range the cameras cover: 360 all around; less leaves the far side of the object unseen"""
    spp: SamplesPerPixel = 256
    """samples per pixel of the ground-truth renders"""
    env_height: MapHeight = 32
    """height of the ground-truth sky map (width is twice this)"""
    environment: str = "sunsky"
    """the ground-truth light: sunsky (Mitsuba's sky from the sun_* fields), a map of the prior's generators,
    outdoor or indoor (drawn by environment_seed from a seed stream the training datasets never use), or a
    panorama file (.exr, .hdr; H x 2H), area-resampled to env_height rows"""
    environment_seed: int = 0
    environment_clip: Rate | None = None
    """clip the map's luminance at this multiple of its median, like an 8-bit panorama decoded through
    the paper's tone curve (the paper's test maps hold no sun); None keeps the full HDR range"""
    sun_elevation_deg: Elevation = 35.0
    sun_azimuth_deg: float = 60.0
    texture_size: TextureSize = 64
    roughness: Fraction = 0.3
    roughness_variation: Fraction = 0.1
    metallic: Fraction = 0.0
    base_roughness: Fraction = 0.05
    base_metallic: Fraction = 1.0
    """the material of a shape's base (the plate of blob_on_plate, its UVs from dpi.synth.shapes.BASE_V up: a
    glossy metal by default, a light grey); shapes without a base ignore both"""
    image_format: str = "exr"
    """format of images/: exr (linear HDR), or png or jpg (sRGB LDR, like photos)"""
    background: str = "env"
    """what the cameras see behind the object: env (the sky), textured (a ground plane and a wall,
    seen but not lighting the object, like a room) or plain (uniform grey, like a studio)"""
    wall_behind: Annotated[float, Field(gt=0)] | None = None
    """with `textured`: the wall is flat, this far behind the object's centre, facing the middle of the cameras'
    arc (a head on a wall, a vase before a bookcase: little parallax between them); None: a wall round the whole
    capture, 2.5 times the cameras' distance away"""
    albedo_detail: Weight = 0.0
    """strength (0-1) of a fine random pattern multiplied into the albedo, like print on a real object:
    features for structure from motion (0: the plain procedural albedo)"""
    scan_faces: Annotated[int, Field(ge=0, le=4_000_000)] = 0
    """0: the given mesh.ply is the truth's own, with its UVs; N: the shape as a scanner gives it instead (at least N
    faces, welded, no UVs: the uv stage simplifies and unwraps it), the truth's mesh in gt/mesh.ply
    (dpi.evaluation.truth carries its textures across)"""
    photos_only: bool = False
    """write only images/ and scene.yaml (with the held-out names), like a folder of photos; the
    cameras, masks and mesh go to gt/ (transforms.json, masks/, mesh.ply) to measure derived ones"""
    layout: str = "dpi"
    """dpi (images/, masks/, transforms.json) or nerf_synthetic (train/ and test/ RGBA PNGs whose alpha is the
    object's coverage, transforms_train.json and transforms_test.json with camera_angle_x and file paths without
    their extension; the held-out views are the test split)"""
    prior: str | None = None
    """scene.yaml `prior` (outdoor | indoor); None writes none, so the scene takes the configured default family"""
    object: str = ""
    """name of the object (scene.yaml `object`; default the shape): scenes of one object under
    different illuminations form the groups of albedo sigma2_invar"""
    seed: int = 0

    @classmethod
    def from_dict(cls, values: dict) -> "SynthConfig":
        """Config from a (possibly partial) dict, e.g. a `synthetic:` entry of config.yaml."""
        values = dict(values)
        if "elevations_deg" in values:
            values["elevations_deg"] = tuple(float(e) for e in values["elevations_deg"])
        return settings_from_dict(cls, values)


def orbit_phase_deg(cfg: SynthConfig) -> float:
    """Azimuth of the capture's first camera (dpi.capture.cameras.orbit's phase): each seed turns the orbit."""
    return cfg.seed * 7.0


def wall_behind(cfg: SynthConfig) -> tuple[np.ndarray, float] | None:
    """(horizontal unit direction towards the middle of the cameras' arc, distance) of a flat wall behind the
    object (SynthConfig.wall_behind), or None."""
    if cfg.wall_behind is None:
        return None
    azimuth = np.radians(orbit_phase_deg(cfg) + (cfg.arc_deg / 2 if cfg.arc_deg < 360 else 0.0))
    return np.array([np.sin(azimuth), 0.0, np.cos(azimuth)]), cfg.wall_behind


def clip_luminance(env: np.ndarray, multiple: float) -> np.ndarray:
    """The map with each texel scaled down so its luminance is at most `multiple` times the median."""
    lum = luminance(env)
    limit = multiple * float(np.median(lum))
    return (env * np.minimum(1.0, limit / np.maximum(lum, 1e-30))[..., None]).astype(np.float32)


def ground_truth_envmap(cfg: SynthConfig) -> np.ndarray:
    """The capture's ground-truth environment: the given EXR, a procedural sunsky, outdoor or indoor map
    (luminance clipped when `environment_clip` is set)."""
    env = procedural_envmap(cfg)
    return env if cfg.environment_clip is None else clip_luminance(env, cfg.environment_clip)


def procedural_envmap(cfg: SynthConfig) -> np.ndarray:
    """The given panorama, a procedural sunsky, outdoor or indoor map, at full range."""
    if cfg.environment not in PROCEDURAL:
        if Path(cfg.environment).suffix.lower() not in PANORAMA_SUFFIXES:
            raise ValueError(f"environment must be {', '.join(PROCEDURAL)} or a panorama file "
                             f"({', '.join(PANORAMA_SUFFIXES)}), got {cfg.environment!r}")
        env = read_panorama(cfg.environment)
        if env.shape[1] != 2 * env.shape[0]:
            raise ValueError(f"{cfg.environment}: environment map must be H x 2H, got {env.shape[:2]}")
        env = env if env.shape[-1] == 3 else np.repeat(env[..., :1], 3, -1)
        return resize_map(torch.from_numpy(env).permute(2, 0, 1), cfg.env_height).permute(1, 2, 0).numpy()
    if cfg.environment in ("outdoor", "indoor"):
        rng = np.random.default_rng([EVALUATION_SEED_STREAM, cfg.environment_seed])
        return generator(cfg.environment)(cfg.env_height, rng, 1)[0].astype(np.float32)
    sky = SkyParams(cfg.sun_elevation_deg, cfg.sun_azimuth_deg)
    return sunsky_envmap(cfg.env_height, sky)


def make_synthetic_capture(out_dir: str | Path, cfg: SynthConfig, threads: int | None = None,
                           progress: bool = True, overwrite: bool = False) -> Path:
    """Render a synthetic capture into `out_dir`; replaces only a folder dpi made, or with `overwrite`."""
    out_dir = Path(out_dir)
    ours = (out_dir / SYNTH_MARKER).exists() or overwrite
    if out_dir.exists() and any(out_dir.iterdir()) and not ours:
        raise FileExistsError(f"{out_dir}: exists and is not a synthetic capture made by dpi; not overwriting")
    if cfg.image_format not in ("exr", "png", "jpg"):
        raise ValueError(f"image_format must be exr, png or jpg, got {cfg.image_format!r}")
    if cfg.layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {', '.join(LAYOUTS)}, got {cfg.layout!r}")
    if cfg.layout == "nerf_synthetic" and (cfg.image_format != "png" or cfg.photos_only):
        raise ValueError("layout nerf_synthetic writes RGBA PNGs with their cameras: image_format png, not photos_only")
    if cfg.scan_faces and cfg.photos_only:
        raise ValueError("scan_faces gives a mesh; photos_only gives none: choose one")
    if cfg.background not in BACKGROUNDS:
        raise ValueError(f"background must be one of {', '.join(BACKGROUNDS)}, got {cfg.background!r}")
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", dir=out_dir.parent))
    try:
        _write_capture(tmp, cfg, threads, progress)
        if out_dir.exists():
            shutil.rmtree(out_dir)
        tmp.rename(out_dir)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)
    return out_dir


def _write_capture(root: Path, cfg: SynthConfig, threads: int | None, progress: bool) -> None:
    """Write every file of the capture into `root` (a fresh folder)."""
    given = root / "gt" if cfg.photos_only else root
    mesh = make_shape(cfg.shape, seed=cfg.seed)
    true_mesh = root / "gt" / "mesh.ply" if cfg.scan_faces else given / "mesh.ply"
    write_ply(true_mesh, mesh)
    if cfg.scan_faces:
        write_mesh_ply(given / "mesh.ply", *scanned(cfg.shape, cfg.seed, cfg.scan_faces))
    materials = procedural_materials(cfg.texture_size, cfg.roughness, cfg.metallic, cfg.roughness_variation,
                                     seed=cfg.seed + 1)
    if cfg.albedo_detail:
        materials.albedo = add_detail(materials.albedo, cfg.albedo_detail, seed=cfg.seed + 2)
    if cfg.shape in BASED_SHAPES:
        base = slice(int(np.floor((BODY_V + BASE_V) / 2 * cfg.texture_size)), None)  # texel rows by v (row 0 at v = 0)
        materials.albedo[base] = BASE_ALBEDO
        materials.roughness[base] = cfg.base_roughness
        materials.metallic[base] = cfg.base_metallic
    ties = SeamTies.of_mesh(mesh.vertices, mesh.faces, mesh.uvs, cfg.texture_size)
    for texture in (materials.albedo, materials.roughness, materials.metallic):  # one value per surface point
        ties.tie_(torch.from_numpy(texture))
    env = ground_truth_envmap(cfg)
    for name, data in (("envmap", env), ("albedo", materials.albedo), ("roughness", materials.roughness),
                       ("metallic", materials.metallic)):
        write_exr(root / "gt" / f"{name}.exr", data)

    poses = orbit(cfg.views, cfg.camera_distance, cfg.elevations_deg, phase_deg=orbit_phase_deg(cfg),
                  arc_deg=cfg.arc_deg)
    names = [f"r_{i:03d}" for i in range(cfg.views)]
    cameras = [from_fov(p, cfg.width, cfg.height, FOV_DEG, n) for p, n in zip(poses, names)]
    for i, cam in enumerate(cameras):
        cam.extras["held_out"] = bool(cfg.held_out_every) and i % cfg.held_out_every == cfg.held_out_every - 1

    renderer = Renderer(true_mesh, cameras, env.shape[0], cfg.texture_size,
                        RenderConfig(spp=cfg.spp, threads=threads))
    tensors = [torch.from_numpy(a) for a in (env, materials.albedo, materials.roughness, materials.metallic)]
    other = "png" if cfg.image_format == "exr" else "exr"
    for i, cam in enumerate(tqdm(cameras, desc="render views", disable=not progress)):
        with torch.no_grad():
            image = renderer.render(*tensors, view=i, seed=10_000 + i).numpy()
        image = np.clip(image, 0.0, None)
        if cfg.background != "env":
            image = composite_backdrop(image, *renderer.object_hits(i, supersample=3), cfg.background, env,
                                       ground=-2.5, wall_radius=2.5 * cfg.camera_distance, seed=cfg.seed,
                                       behind=wall_behind(cfg))
        if cfg.layout == "nerf_synthetic":
            split = "test" if cam.extras["held_out"] else "train"
            write_srgb_alpha(root / split / f"{cam.name}.png", image, renderer.coverage(i))
            continue
        for fmt, folder in ((cfg.image_format, "images"), (other, "preview")):
            path = root / folder / f"{cam.name}.{fmt}"
            write_exr(path, image) if fmt == "exr" else write_srgb(path, image)  # png or jpg
        write_mask(given / "masks" / f"{cam.name}.png", renderer.coverage(i) >= 0.5)

    if cfg.layout == "nerf_synthetic":
        write_nerf_synthetic_splits(root, cameras)
    else:
        frames = [(f"images/{cam.name}.{cfg.image_format}", cam) for cam in cameras]
        write_json(given / "transforms.json", write_transforms(frames))
    scene = {**({"prior": cfg.prior} if cfg.prior else {}), "object": cfg.object or cfg.shape}
    if cfg.photos_only:
        scene["held_out"] = [cam.name for cam in cameras if cam.extras["held_out"]]
        scene["focal_length_px"] = float(cameras[0].fx)  # what a photo's EXIF would tell
    write_text(root / "scene.yaml", yaml.safe_dump(scene, sort_keys=False))
    write_json(root / SYNTH_MARKER, asdict(cfg))


def scanned(shape: str, seed: int, faces: int) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) of `shape` as a scanner gives it: the same surface at the first resolution with at least
    `faces` faces, its seam copies welded, without UVs."""
    import trimesh

    resolution = 8
    while len((mesh := make_shape(shape, resolution, seed)).faces) < faces:
        resolution = int(np.ceil(resolution * max(1.1, np.sqrt(faces / len(mesh.faces)))))
    welded = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    welded.merge_vertices(merge_tex=True, merge_norm=True)
    welded.remove_unreferenced_vertices()
    return np.asarray(welded.vertices), np.asarray(welded.faces)


def write_nerf_synthetic_splits(root: Path, cameras: list) -> None:
    """transforms_train.json and transforms_test.json as NeRF-synthetic writes them: camera_angle_x, and per frame
    a file path without its extension and the camera-to-world matrix (OpenGL axes)."""
    for split, held in (("train", False), ("test", True)):
        chosen = [cam for cam in cameras if cam.extras["held_out"] == held]
        if not chosen:
            continue
        angle = 2.0 * float(np.arctan(chosen[0].width / (2.0 * chosen[0].fx)))
        frames = [{"file_path": f"./{split}/{cam.name}", "rotation": 0.0, "transform_matrix": cam.c2w.tolist()}
                  for cam in chosen]
        write_json(root / f"transforms_{split}.json", {"camera_angle_x": angle, "frames": frames})


def read_marker(capture_dir: str | Path) -> dict | None:
    """The parameters a synthetic capture was made with, or None for other captures."""
    path = Path(capture_dir) / SYNTH_MARKER
    return json.loads(path.read_text()) if path.is_file() else None
