"""Geometry that cannot be right, caught before any job: a mesh wound inwards is turned outwards (the cameras see
it from behind), a mesh no camera sees is named as misplaced, and a mesh in other units is named with them."""

from __future__ import annotations

import json

import pytest
import trimesh
from capture_helpers import make_capture

from dpi.capture import CaptureError, load_capture
from dpi.capture.consistency import back_facing_fraction
from dpi.preprocess.derive import normalise_capture


def moved_mesh(root, scale=1.0, shift=(0.0, 0.0, 0.0), invert=False):
    mesh = trimesh.load(root / "mesh.ply", force="mesh", process=False)
    mesh.apply_scale(scale)
    mesh.apply_translation(shift)
    if invert:
        mesh.invert()
    mesh.export(root / "mesh.ply")


def test_a_mesh_wound_inwards_is_turned_outwards_at_capture_time(tmp_path):
    root = make_capture(tmp_path / "s")
    moved_mesh(root, invert=True)
    normalise_capture(root, tmp_path / "out" / "capture.json")
    written = json.loads((tmp_path / "out" / "capture.json").read_text())["mesh"]
    assert written.startswith(str(tmp_path / "out"))
    mesh = trimesh.load(written, force="mesh", process=False)
    cameras = [v.camera for v in load_capture(root).views]
    assert back_facing_fraction(mesh.vertices, mesh.faces, cameras) < 0.05


def test_a_mesh_no_camera_sees_is_named_as_misplaced(tmp_path):
    root = make_capture(tmp_path / "s")
    moved_mesh(root, shift=(0.0, 40.0, 0.0))
    with pytest.raises(CaptureError, match="placement: .*the mesh and the cameras are in different frames"):
        load_capture(root)


def test_a_mesh_in_other_units_is_named_with_them(tmp_path):
    root = make_capture(tmp_path / "s")
    moved_mesh(root, scale=0.01)
    with pytest.raises(CaptureError, match=r"scale: .* \(about 0\.0\d+x: centimetres against metres"):
        load_capture(root)
