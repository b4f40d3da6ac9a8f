"""Stages of rules/preprocess.smk: a synthetic scene's capture, the validated capture.json, and what a photo
capture lacks (poses -> masks -> geometry -> uv). Which of the last four a scene needs (`needed_stages`) and
which derived files each reads (`stage_inputs`) are decided here once, from what the capture gives; the rules
and `dpi preprocess` both ask."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from dpi.capture import complete_capture, read_capture_json
from dpi.io.layout import SceneLayout
from dpi.preprocess.derive import derive_geometry, derive_poses, derive_uv, derive_view_masks, normalise_capture
from dpi.solve.problem import texture_size_for
from dpi.stages.job import StageJob
from dpi.synth.capture import make_synthetic_capture

STAGES = ("poses", "masks", "geometry", "uv")
"""the preprocessing stages after the capture's, in order"""

log = logging.getLogger(__name__)


def needed_stages(given: dict[str, bool]) -> list[str]:
    """The stages a capture needs, in order, from what it gives (`dpi.capture.inspect_capture`): poses
    without cameras or masks (the masks stage reads its sparse points), masks without masks, geometry without a
    mesh, uv without a mesh with UVs."""
    needed = {"poses": not (given["cameras"] and given["masks"]), "masks": not given["masks"],
              "geometry": not given["mesh"],
              "uv": not given["mesh_has_uv"]}
    return [stage for stage in STAGES if needed[stage]]


def stage_inputs(stage: str, given: dict[str, bool], scene: SceneLayout) -> dict[str, Path]:
    """The derived files a preprocessing stage reads besides capture.json, keyed by its function's argument
    names: the outputs of the stages before it, for what the capture does not give."""
    cameras = {} if given["cameras"] else {"cameras_json": scene.poses["cameras"]}
    if stage == "masks":
        return {**cameras, "points_ply": scene.poses["points"]}
    if stage == "geometry":
        return {**cameras, **({} if given["masks"] else {"masks_dir": scene.masks})}
    if stage == "uv":  # the masks say how large the textures are (dpi.solve.problem.texture_size_for)
        return {**({} if given["mesh"] else {"mesh": scene.geometry["mesh"]}),
                **({} if given["masks"] else {"masks_dir": scene.masks})}
    return {}


def synth_capture_stage(job: StageJob) -> None:
    """Render a synthetic scene's capture folder, with its ground truth, from its `synthetic:` entry."""
    make_synthetic_capture(job.capture_dir, job.pipeline.synth_settings(job.scene), threads=job.threads,
                           overwrite=True, progress=job.progress)


def capture_stage(job: StageJob) -> None:
    """Validate the scene's capture folder once into capture.json (dpi.preprocess.derive.normalise_capture)."""
    normalise_capture(job.capture_dir, job.paths.capture_json)


def _inputs(job: StageJob, stage: str) -> dict[str, Path]:
    return stage_inputs(stage, job.given, job.paths)


def _settings(job: StageJob, section: str) -> dict[str, Any]:
    return job.config["preprocess"][section]


def poses_stage(job: StageJob) -> dict:
    """The scene's cameras, sparse points and a summary (structure from motion, or the capture's COLMAP model)."""
    return derive_poses(job.paths.capture_json, job.paths.poses_dir, _settings(job, "sfm"), job.threads)


def masks_stage(job: StageJob) -> dict:
    """Foreground masks of every view with a camera, and a summary."""
    return derive_view_masks(job.paths.capture_json, job.paths.masks, _settings(job, "masks"), threads=job.threads,
                             **_inputs(job, "masks"))


def geometry_stage(job: StageJob) -> dict:
    """The carved and cleaned surface of the object, and a summary."""
    return derive_geometry(job.paths.capture_json, job.paths.geometry_dir, _settings(job, "geometry"),
                           threads=job.threads, **_inputs(job, "geometry"))


def uv_stage(job: StageJob) -> dict:
    """The UV atlas of the derived mesh (or of the capture's mesh without UVs), packed for the textures' size
    (dpi.solve.problem.texture_size_for), and a summary."""
    capture = complete_capture(read_capture_json(job.paths.capture_json), job.paths, ("masks",))
    mesh = _inputs(job, "uv").get("mesh")
    return derive_uv(job.paths.capture_json, job.paths.geometry_dir, texture_size_for(capture, job.solve.problem),
                     _settings(job, "uv"), mesh)


RUN = {"poses": poses_stage, "masks": masks_stage, "geometry": geometry_stage, "uv": uv_stage}
"""each preprocessing stage's function"""


def preprocess_scene(job: StageJob) -> dict[str, Any]:
    """What the preprocessing rules do for one scene, without Snakemake: capture.json, then the stages the
    capture needs, in order. Returns each stage's summary, or "given"."""
    capture_stage(job)
    report: dict[str, Any] = dict.fromkeys(STAGES, "given")
    for stage in needed_stages(job.given):
        log.info("preprocess %s: %s", job.scene, stage)
        report[stage] = RUN[stage](job)
    return report
