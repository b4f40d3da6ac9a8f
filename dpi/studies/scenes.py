"""The studies' synthetic scenes: sizes shared by every study and the posterior study's scene set.

Each scene is (group, synthetic capture settings for dpi.synth.capture.SynthConfig); the illuminations
come from seed streams no prior trained on, or from Mitsuba's sunsky."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from dpi.io.layout import Layout

SIZE = {"views": 8, "held_out_every": 4, "width": 32, "height": 32, "spp": 128, "env_height": 32,
        "texture_size": 32}
"""views, image and map sizes of the small study captures"""
AMBIGUOUS = {**SIZE, "roughness": 0.7, "roughness_variation": 0.1, "metallic": 0.0, "arc_deg": 150.0,
             "elevations_deg": (15.0, 40.0)}
"""a rough dielectric seen on a limited arc: where the views leave the light open"""
MIXED = {**SIZE, "shape": "blob_on_plate", "views": 24, "width": 48, "height": 48, "camera_distance": 6.0,
         "roughness": 0.7, "roughness_variation": 0.1, "metallic": 0.0, "arc_deg": 360.0,
         "elevations_deg": (25.0, 50.0)}
"""a rough body on a glossy metal plate seen all around from above: the plate's reflections tell the light's broad
balance (sky against ground) that the body alone leaves to the albedo"""
GLOSSY = {**SIZE, "roughness": 0.08, "roughness_variation": 0.0, "metallic": 1.0, "arc_deg": 360.0}
"""a shiny metal seen from all around: where a free fit already recovers the light"""

SCAN_FACES = 60_000
"""faces of a scanned scene's given mesh (SynthConfig.scan_faces): far more than its textures resolve"""

POSTERIOR_SCENES: dict[str, tuple[str, dict[str, Any]]] = {
    "blob_sun": ("ambiguous", {**AMBIGUOUS, "shape": "blob", "seed": 0, "environment": "outdoor",
                               "environment_seed": 11, "prior": "outdoor"}),
    "blob_room": ("ambiguous", {**AMBIGUOUS, "shape": "blob", "seed": 0, "environment": "indoor",
                                "environment_seed": 12, "prior": "indoor"}),
    "blob_ldr": ("ambiguous", {**AMBIGUOUS, "shape": "blob", "seed": 0, "environment": "outdoor",
                               "environment_seed": 13, "environment_clip": 5.3, "prior": "outdoor"}),
    "torus_sun": ("ambiguous", {**AMBIGUOUS, "shape": "bumpy_torus", "seed": 3, "environment": "sunsky",
                                "sun_elevation_deg": 25.0, "sun_azimuth_deg": 200.0, "prior": "outdoor"}),
    "torus_room": ("ambiguous", {**AMBIGUOUS, "shape": "bumpy_torus", "seed": 3, "environment": "indoor",
                                 "environment_seed": 14, "prior": "indoor"}),
    "torus_ldr": ("ambiguous", {**AMBIGUOUS, "shape": "bumpy_torus", "seed": 3, "environment": "outdoor",
                                "environment_seed": 15, "environment_clip": 5.3, "prior": "outdoor"}),
    "blob_glossy": ("glossy", {**GLOSSY, "shape": "blob", "seed": 5, "environment": "outdoor",
                               "environment_seed": 16, "prior": "outdoor"}),
    "torus_scan": ("scan", {**AMBIGUOUS, "shape": "bumpy_torus", "seed": 9, "scan_faces": SCAN_FACES,
                            "environment": "outdoor", "environment_seed": 17, "prior": "outdoor"}),
}
"""the posterior study's scenes: six ambiguous (two objects under a sun, a room, a clipped map), one glossy, and one
ambiguous object given as a scanner gives it (`scan`: a dense mesh without UVs, unwrapped by the uv stage)"""

REAL_LIGHT_SCENES: dict[str, tuple[str, dict[str, Any]]] = {
    "blob_overpass": ("real", {**AMBIGUOUS, "shape": "blob", "seed": 0, "panorama": "pedestrian_overpass_1k.hdr",
                               "prior": "outdoor"}),
    "torus_venice": ("real", {**AMBIGUOUS, "shape": "bumpy_torus", "seed": 3, "panorama": "venice_sunset_1k.hdr",
                              "prior": "outdoor"}),
    "blob_forest": ("real", {**AMBIGUOUS, "shape": "blob", "seed": 1, "panorama": "phalzer_forest_01_1k.hdr",
                             "prior": "outdoor"}),
    "torus_market": ("real", {**AMBIGUOUS, "shape": "bumpy_torus", "seed": 4, "panorama": "leadenhall_market_1k.hdr",
                              "prior": "indoor"}),
    "blob_studio": ("real", {**AMBIGUOUS, "shape": "blob", "seed": 2, "panorama": "brown_photostudio_02_1k.hdr",
                             "prior": "indoor"}),
    "plate_overpass": ("real_mixed", {**MIXED, "seed": 7, "panorama": "pedestrian_overpass_1k.hdr",
                                      "prior": "outdoor"}),
    "plate_spree": ("real_mixed", {**MIXED, "seed": 8, "panorama": "spree_bank_1k.hdr", "prior": "outdoor"}),
    "blob_beach_glossy": ("real_glossy", {**GLOSSY, "shape": "blob", "seed": 5,
                                          "panorama": "spiaggia_di_mondello_1k.hdr", "prior": "outdoor"}),
    "torus_vestibule_glossy": ("real_glossy", {**GLOSSY, "shape": "bumpy_torus", "seed": 6,
                                               "panorama": "vestibule_1k.hdr", "prior": "indoor"}),
}
"""the posterior study's real-light scenes: rough objects seen on an arc (group `real`), a rough body on a glossy
plate seen all around from above under two city panoramas (`real_mixed`) and metals seen all around
(`real_glossy`) under the manifest's held-out real panoramas (dpi/data/panoramas.csv: a city, a low sun, a forest,
a market hall, a studio, a beach, a vestibule), which no prior trained on; the maps do not ship
(`real_light_scenes`)"""


DEV_SCENES: dict[str, tuple[str, dict[str, Any]]] = {
    "dev_blob_hills": ("dev_real", {**AMBIGUOUS, "shape": "blob", "seed": 21, "panorama": "hilly_terrain_01_1k.hdr",
                                    "prior": "outdoor"}),
    "dev_torus_piazza": ("dev_real", {**AMBIGUOUS, "shape": "bumpy_torus", "seed": 22,
                                      "panorama": "piazza_bologni_1k.hdr", "prior": "outdoor"}),
    "dev_blob_autoshop": ("dev_real", {**AMBIGUOUS, "shape": "blob", "seed": 23, "panorama": "autoshop_01_1k.hdr",
                                       "prior": "indoor"}),
    "dev_torus_studio": ("dev_real", {**AMBIGUOUS, "shape": "bumpy_torus", "seed": 24,
                                      "panorama": "studio_small_08_1k.hdr", "prior": "indoor"}),
    "dev_plate_piazza": ("dev_mixed", {**MIXED, "seed": 27, "panorama": "piazza_bologni_1k.hdr",
                                       "prior": "outdoor"}),
    "dev_plate_hills": ("dev_mixed", {**MIXED, "seed": 28, "panorama": "hilly_terrain_01_1k.hdr",
                                      "prior": "outdoor"}),
    "dev_blob_sun": ("dev_ambiguous", {**AMBIGUOUS, "shape": "blob", "seed": 25, "environment": "outdoor",
                                       "environment_seed": 61, "prior": "outdoor"}),
    "dev_torus_room": ("dev_ambiguous", {**AMBIGUOUS, "shape": "bumpy_torus", "seed": 26, "environment": "indoor",
                                         "environment_seed": 62, "prior": "indoor"}),
}
"""scenes for choosing a sampler's design, apart from every study's: other objects, the held-out panoramas the
posterior study does not use, and procedural maps of other seeds (`posterior_study.py --dev`)"""


HELD_OUT_LIGHT_SCENES: dict[str, tuple[str, dict[str, Any]]] = {
    "ho_torus_overpass": ("held_out_real", {**AMBIGUOUS, "shape": "bumpy_torus", "seed": 41, "arc_deg": 120.0,
                                            "elevations_deg": (30.0, 55.0), "panorama": "pedestrian_overpass_1k.hdr",
                                            "prior": "outdoor"}),
    "ho_blob_venice": ("held_out_real", {**AMBIGUOUS, "shape": "blob", "seed": 42, "arc_deg": 200.0,
                                         "elevations_deg": (5.0, 30.0), "panorama": "venice_sunset_1k.hdr",
                                         "prior": "outdoor"}),
    "ho_torus_market": ("held_out_real", {**AMBIGUOUS, "shape": "bumpy_torus", "seed": 43, "arc_deg": 180.0,
                                          "panorama": "leadenhall_market_1k.hdr", "prior": "indoor"}),
    "ho_blob_provence": ("held_out_real", {**AMBIGUOUS, "shape": "blob", "seed": 44, "arc_deg": 120.0,
                                           "elevations_deg": (20.0, 45.0), "panorama": "provence_studio_1k.exr",
                                           "prior": "indoor"}),
    "ho_plate_venice": ("held_out_mixed", {**MIXED, "seed": 45, "views": 16, "elevations_deg": (35.0, 60.0),
                                           "panorama": "venice_sunset_1k.hdr", "prior": "outdoor"}),
}
"""scenes no study and no design run uses, for judging a design once it is chosen: other objects and cameras (other
arcs and heights) under held-out panoramas, one of them no other scene uses (`posterior_study.py --held-out`)"""


STUDY_SCENES = {**POSTERIOR_SCENES, **REAL_LIGHT_SCENES, **DEV_SCENES, **HELD_OUT_LIGHT_SCENES}
"""every scene of the posterior study's folders by name (the study's, real light, design, held out)"""


def drawn_scenes(works: Iterable[Path], names: Iterable[str] | None = None) -> Iterator[tuple[str, Path]]:
    """(name, results folder) of each STUDY_SCENES scene the study folders `works` hold (its capture.json written),
    among `names` (default: every one), in name order within each folder."""
    wanted = None if names is None else set(names)
    for work in works:
        layout = Layout.of_study(work)
        for name in sorted(p.parent.name for p in layout.results.glob("*/capture.json")):
            if name in STUDY_SCENES and (wanted is None or name in wanted):
                yield name, layout.scene(name).capture_json.parent


def real_light_scenes(folder: Path, scenes: dict[str, tuple[str, dict[str, Any]]] = REAL_LIGHT_SCENES
                      ) -> dict[str, tuple[str, dict[str, Any]]]:
    """`scenes` (REAL_LIGHT_SCENES) with a panorama lit by the file of that name in `folder`, each checked against
    the manifest's checksum; the others as they are."""
    from dpi.prior.panoramas import panorama_files

    held_out = {path.name: path for family in ("outdoor", "indoor")
                for path in panorama_files(folder, family, "held_out")}
    lit = {}
    for name, (group, synth) in scenes.items():
        panorama = synth.get("panorama")
        if panorama is not None and panorama not in held_out:
            raise FileNotFoundError(f"{folder}: no {panorama} (scene {name}); dpi/data/panoramas.csv says where it is")
        lit[name] = (group, synth) if panorama is None else (group, {
            **{k: v for k, v in synth.items() if k != "panorama"}, "environment": str(held_out[panorama].resolve())})
    return lit


CALIBRATION_OBJECTS = {"blob": {"shape": "blob", "seed": 0}, "torus": {"shape": "bumpy_torus", "seed": 3}}
CALIBRATION_LIGHTS = {"sun": {"environment": "outdoor", "environment_seed": 21, "prior": "outdoor"},
                      "room": {"environment": "indoor", "environment_seed": 22, "prior": "indoor"},
                      "ldr": {"environment": "outdoor", "environment_seed": 23, "environment_clip": 5.3,
                              "prior": "outdoor"}}
CALIBRATION_MATERIALS = {"metal": {"roughness": 0.05, "roughness_variation": 0.0, "metallic": 1.0},
                         "rough": {"roughness": 0.85, "roughness_variation": 0.05, "metallic": 0.0}}


def calibration_scenes() -> dict[str, dict[str, Any]]:
    """The calibration study's scenes, OBJECT_LIGHT_MATERIAL -> synthetic capture (without the repeat's seed)."""
    return {f"{o}_{light}_{m}": {**SIZE, "arc_deg": 150.0, "elevations_deg": (15.0, 40.0), **CALIBRATION_OBJECTS[o],
                                 **CALIBRATION_LIGHTS[light], **CALIBRATION_MATERIALS[m], "object": o}
            for o in CALIBRATION_OBJECTS for light in CALIBRATION_LIGHTS for m in CALIBRATION_MATERIALS}


def repeat_scene(scene: str, repeat: int) -> str:
    """The folder of one repeat of a scene: its own capture noise and initialisation."""
    return f"{scene}_r{repeat}"


def repeat_synth(synth: dict[str, Any], repeat: int) -> dict[str, Any]:
    """A repeat's synthetic capture: its own render noise and object seed."""
    return {**synth, "seed": synth["seed"] + 100 * repeat}


ROUGHNESS_CAPTURE = {"object": "sweep", "shape": "blob", "seed": 0, "views": 10, "held_out_every": 5, "width": 32,
                     "height": 32, "spp": 64, "environment": "outdoor", "environment_seed": 31,
                     "roughness_variation": 0.0, "prior": "outdoor"}
"""the roughness study's object: a blob seen by 8 training views of 32 px under a natural map with buildings and a
sun (a mirror of a featureless sky shows little more than a rough object does)"""
MIRROR_LIKE = 0.1
"""the roughness study's objects at or below this roughness are metallic, the others dielectric (the paper's sweep)"""


def roughness_scenes(values: list[float]) -> dict[str, dict[str, Any]]:
    """The roughness study's scenes, one per roughness: rough_R -> synthetic capture (without the repeat's seed)."""
    return {f"rough_{r:.3f}": {**ROUGHNESS_CAPTURE, "roughness": r, "metallic": 1.0 if r <= MIRROR_LIKE else 0.0}
            for r in values}


RESOLUTION_CAPTURE = {"views": 12, "held_out_every": 4, "width": 96, "height": 96, "spp": 128, "env_height": 256,
                      "texture_size": 128, "arc_deg": 150.0, "elevations_deg": (15.0, 40.0), "environment": "sunsky",
                      "sun_elevation_deg": 12.0, "sun_azimuth_deg": 200.0, "prior": "outdoor"}
RESOLUTION_SCENES = {
    "torus_glossy": ("glossy", {**RESOLUTION_CAPTURE, "shape": "bumpy_torus", "seed": 3, "roughness": 0.05,
                                "roughness_variation": 0.0, "metallic": 1.0}),
    "blob_rough": ("rough", {**RESOLUTION_CAPTURE, "shape": "blob", "seed": 0, "roughness": 0.85,
                             "roughness_variation": 0.05, "metallic": 0.0})}
"""the resolution study's scenes: a mirror-like metal torus and a rough blob under a low sun, views of 96 px"""


def resolution_config(height: int, texture: int) -> dict[str, Any]:
    """The workflow's resolved config at a map height and texture size."""
    from dpi.studies.engine import workflow_config

    return workflow_config(height, texture)


def resolution_root(work: Path, height: int, texture: int) -> Path:
    """One size's study folder under `work`; its captures/ links to the shared one (captures do not depend on
    the size)."""
    root = work / f"h{height}_t{texture}"
    (root / "results").mkdir(parents=True, exist_ok=True)
    link = root / "captures"
    if not link.exists():
        link.symlink_to(work / "captures", target_is_directory=True)
    return root
