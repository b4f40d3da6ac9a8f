"""A real photo capture (tests/data/skull_photos): a skull on a stand, 25 flash photos of 640 x 427 with the
cameras COLMAP fitted (CC BY 4.0, its LICENSE.md); masks, geometry and UVs are
derived as the workflow derives them."""

from pathlib import Path

import numpy as np
import pytest

from dpi.io.images import read_mask
from dpi.stages import preprocess_scene
from stage_jobs import stage_job

SKULL = Path(__file__).parent / "data" / "skull_photos"


@pytest.fixture(scope="module")
def derived(tmp_path_factory):
    # stereo carving (two minutes here) is tested on synthetic captures; these photos test the masks and the hull
    job = stage_job(SKULL, tmp_path_factory.mktemp("skull"), preprocess={"geometry": {"stereo": False}})
    return job.paths, preprocess_scene(job)


def test_masks_hold_on_real_photos(derived):
    """Every view gets a mask of the skull (a third of the frame or so); at most two views are flagged."""
    scene, report = derived
    assert report["poses"] == "given"
    masks = report["masks"]
    assert len(masks["views"]) == 25 and len(masks["unreliable"]) <= 2
    fractions = [read_mask(scene.masks / f"{view}.png").mean() for view in masks["views"]]
    assert 0.1 < min(fractions) and max(fractions) < 0.6


def test_geometry_of_a_real_capture_is_one_closed_object_with_uvs(derived):
    scene, report = derived
    import trimesh

    mesh = trimesh.load(scene.geometry_dir / "mesh_uv.ply", process=False)
    assert len(mesh.faces) > 1000 and np.isfinite(mesh.vertices).all()
    assert report["uv"] != "given"
