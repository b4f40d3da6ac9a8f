"""A real photo capture (tests/data/skull_photos): a skull on a stand, 25 flash photos of 640 x 427 with the
cameras COLMAP fitted (CC BY 4.0, its LICENSE.md); sparse points, masks, geometry and UVs are derived as the
workflow derives them."""

from pathlib import Path

import numpy as np
import pytest

from dpi.io.images import read_mask
from dpi.stages import preprocess_scene
from stage_jobs import stage_job

SKULL = Path(__file__).parent / "data" / "skull_photos"

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def derived(tmp_path_factory):
    # stereo carving (two minutes here) is tested on synthetic captures and the parallax seeds on the busy street's
    # photos (test_real_photos_busy); these photos test the colour masks, their flags and the hull
    job = stage_job(SKULL, tmp_path_factory.mktemp("skull"),
                    preprocess={"geometry": {"stereo": False}, "masks": {"parallax": False}})
    return job.paths, preprocess_scene(job)


def test_masks_hold_on_real_photos(derived):
    """Every view gets a mask of the skull (a third of the frame or so), from points triangulated under the given
    cameras; the views flagged are those whose mask took the stand's post out of the frame, and they are the worse
    ones against the checked masks."""
    from dpi.capture.consistency import mask_iou

    scene, report = derived
    assert report["poses"]["cameras"] == "given" and report["poses"]["points"] > 100
    masks = report["masks"]
    assert len(masks["views"]) == 25 and len(masks["unreliable"]) <= 8
    fractions = [read_mask(scene.masks / f"{view}.png").mean() for view in masks["views"]]
    assert 0.1 < min(fractions) and max(fractions) < 0.6
    assert all("frame's edge" in masks["views"][view]["why"] for view in masks["unreliable"])
    iou = {view: mask_iou(read_mask(scene.masks / f"{view}.png"), read_mask(SKULL / "checked_masks" / f"{view}.png"))
           for view in masks["views"]}
    flagged = [iou[v] for v in masks["unreliable"]]
    kept = [iou[v] for v in masks["views"] if v not in masks["unreliable"]]
    assert np.mean(flagged) < np.mean(kept) - 0.03 and np.median(kept) > 0.93


def test_geometry_of_a_real_capture_is_one_closed_object_with_uvs(derived):
    scene, report = derived
    import trimesh

    mesh = trimesh.load(scene.geometry_dir / "mesh_uv.ply", process=False)
    assert len(mesh.faces) > 1000 and np.isfinite(mesh.vertices).all()
    assert report["uv"] != "given"
