"""Synthetic captures: procedural shapes, materials, the written capture, and its safety rules."""

import json

import numpy as np
import pytest

from dpi.capture import load_capture
from dpi.io.exr import read_exr, write_exr
from dpi.io.images import read_mask
from dpi.io.layout import SYNTH_MARKER
from dpi.synth.backdrop import backdrop_hits
from dpi.synth.capture import SynthConfig, ground_truth_envmap, make_synthetic_capture, wall_behind
from dpi.synth.shapes import SHAPES, make_shape
from dpi.synth.textures import procedural_materials


@pytest.mark.parametrize("name", SHAPES)
def test_shapes_are_closed_outward_surfaces_with_uvs(name):
    mesh = make_shape(name, resolution=24)
    v, f = mesh.vertices, mesh.faces
    assert mesh.uvs.min() >= 0 and mesh.uvs.max() <= 1 and len(mesh.uvs) == len(v)
    # Divergence theorem: signed volume > 0 iff faces are wound with outward normals.
    volume = np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6
    assert volume > 0.3


def test_materials_are_in_range_and_structured():
    m = procedural_materials(32, roughness=0.4, metallic=0.2, seed=1)
    assert m.albedo.shape == (32, 32, 3) and m.roughness.shape == (32, 32, 1)
    assert 0 < m.albedo.min() and m.albedo.max() <= 1 and m.albedo.std() > 0.05
    assert abs(float(m.roughness.mean()) - 0.4) < 0.1 and np.allclose(m.metallic, 0.2)


def test_capture_is_complete_and_valid(tiny_capture):
    capture = load_capture(tiny_capture)
    assert len(capture.views) == 5 and [v.name for v in capture.held_out_views] == ["r_004"]
    assert capture.mesh_has_uv and set(capture.gt) == {"envmap", "albedo", "roughness", "metallic"}
    assert all(p == "given" for p in capture.provenance.values())
    env = read_exr(tiny_capture / "gt" / "envmap.exr")
    assert env.shape == (8, 16, 3) and np.isfinite(env).all()
    masks = [read_mask(v.mask) for v in capture.views]
    assert all(0.1 < m.mean() < 0.9 for m in masks)
    assert json.loads((tiny_capture / SYNTH_MARKER).read_text())["views"] == 5


def test_refuses_to_overwrite_a_foreign_folder(tmp_path):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "photo.jpg").write_bytes(b"x")
    with pytest.raises(FileExistsError, match="not a synthetic capture"):
        make_synthetic_capture(tmp_path / "mine", SynthConfig(views=1))
    assert (tmp_path / "mine" / "photo.jpg").exists()


def test_unknown_settings_are_rejected():
    with pytest.raises(ValueError, match="colour"):
        SynthConfig.from_dict({"colour": 1})


@pytest.mark.parametrize("family", ["outdoor", "indoor"])
def test_procedural_ground_truth_maps_are_seeded_and_distinct_per_seed(family):
    maps = [ground_truth_envmap(SynthConfig(environment=family, environment_seed=s, env_height=8)) for s in (0, 0, 1)]
    assert maps[0].shape == (8, 16, 3) and np.isfinite(maps[0]).all() and (maps[0] >= 0).all()
    same, other = np.abs(maps[0] - maps[1]).mean(), np.abs(maps[0] - maps[2]).mean()
    assert same < 0.3 * other  # indoor maps are path traced: equal up to Monte Carlo noise


def test_unknown_environment_is_rejected():
    with pytest.raises(ValueError, match="environment"):
        ground_truth_envmap(SynthConfig(environment="moon"))


def test_a_given_panorama_is_area_resampled_to_the_capture_map_height(tmp_path):
    """A user's panorama lights the capture at env_height rows, its mean radiance kept."""
    panorama = np.random.default_rng(0).gamma(1.0, 2.0, (16, 32, 3)).astype(np.float32)
    write_exr(tmp_path / "sky.exr", panorama)
    env = ground_truth_envmap(SynthConfig.from_dict({"environment": str(tmp_path / "sky.exr"), "env_height": 8}))
    assert env.shape == (8, 16, 3)
    np.testing.assert_allclose(env.mean(axis=(0, 1)), panorama.mean(axis=(0, 1)), rtol=1e-5)


def test_a_wall_behind_is_met_behind_the_object_facing_the_arcs_middle():
    cfg = SynthConfig(arc_deg=180.0, wall_behind=2.0, camera_distance=6.0)
    normal, distance = wall_behind(cfg)
    assert np.isclose(np.linalg.norm(normal), 1.0) and normal[1] == 0.0
    camera = 6.0 * normal  # the arc's middle camera, looking at the centre and past it
    dirs = np.array([-normal, -normal + [0.0, 0.1, 0.0], normal])
    uv, hit = backdrop_hits(np.tile(camera, (3, 1)), dirs / np.linalg.norm(dirs, axis=1, keepdims=True), -2.5, 15.0,
                            (normal, distance))
    assert hit.tolist() == [True, True, False]  # straight at the wall, a little up, and away from it (over nothing)
    np.testing.assert_allclose(uv[0], [0.0, 0.0], atol=1e-9)  # the wall's point straight behind the centre
    assert wall_behind(SynthConfig(arc_deg=180.0)) is None
