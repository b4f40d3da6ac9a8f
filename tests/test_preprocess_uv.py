"""UV atlas (xatlas) and the texel convention, checked through Mitsuba: bake, look up, compare."""

from __future__ import annotations

import numpy as np
import pytest

from dpi.preprocess.uv import bake, uv_atlas, write_uv_mesh
from dpi.render.texels import chart_texels, fill_gutters, rasterize_uv, texel_values, texture_from
from dpi.synth.shapes import blob


def colour_field(points: np.ndarray) -> np.ndarray:
    """A smooth RGB function of position in [0, 1]."""
    x, y, z = points.T
    return 0.5 + 0.5 * np.stack([np.sin(2 * x), np.sin(3 * y + 1), np.sin(2 * z - x)], -1)


@pytest.fixture(scope="module")
def atlas():
    import trimesh

    shape = blob(resolution=24, seed=2)
    merged = trimesh.Trimesh(shape.vertices, shape.faces, process=False)
    merged.merge_vertices()
    mesh, summary = uv_atlas(np.asarray(merged.vertices), np.asarray(merged.faces), 128)
    return mesh, summary


def test_atlas_covers_every_face_inside_the_unit_square(atlas):
    mesh, summary = atlas
    assert summary["faces"] == len(mesh.faces) and len(mesh.uvs) == len(mesh.vertices)
    assert mesh.uvs.min() >= 0 and mesh.uvs.max() <= 1
    index, bary = rasterize_uv(mesh.uvs, mesh.faces, 128)
    covered = index >= 0
    assert 0.3 < covered.mean() < 0.95  # charts are packed with gutters between them
    np.testing.assert_allclose(bary[covered].sum(-1), 1.0, atol=1e-9)
    assert (bary[covered] >= -1e-9).all()


def test_vertex_values_bake_as_the_surface_points_do(atlas):
    """Per-vertex positions interpolated over the texels are the texels' surface points (a linear function bakes the
    same either way)."""
    mesh, _ = atlas
    interpolated = texture_from(*texel_values(mesh.uvs, mesh.faces, mesh.vertices, 64))
    np.testing.assert_allclose(interpolated, bake(mesh, lambda p: p, 64), atol=1e-6)


def test_baked_texture_reads_back_through_mitsuba(atlas, mi, tmp_path):
    mesh, _ = atlas
    size = 128
    texture = bake(mesh, colour_field, size)
    write_uv_mesh(tmp_path / "mesh_uv.ply", mesh)
    scene = mi.load_dict({"type": "scene", "object": {"type": "ply", "filename": str(tmp_path / "mesh_uv.ply")}})
    rng = np.random.default_rng(0)
    origins = rng.normal(size=(4000, 3))
    origins = 3 * origins / np.linalg.norm(origins, axis=1, keepdims=True)
    dirs = -origins + rng.normal(scale=0.3, size=origins.shape)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    ray = mi.Ray3f(mi.Point3f(*origins.T.astype(np.float32)), mi.Vector3f(*dirs.T.astype(np.float32)))
    si = scene.ray_intersect(ray)
    hit = np.array(si.is_valid())
    points = np.array(si.p).reshape(3, -1).T[hit]
    errors = {}
    for name, data in (("dpi", texture), ("rows flipped", texture[::-1].copy())):
        bitmap = mi.load_dict({"type": "bitmap", "bitmap": mi.Bitmap(data), "raw": True, "filter_type": "bilinear"})
        looked_up = np.array(bitmap.eval(si)).reshape(3, -1).T[hit]
        errors[name] = np.abs(looked_up - colour_field(points)).mean()
    assert hit.sum() > 3000
    assert errors["dpi"] < 0.005, errors
    assert errors["rows flipped"] > 0.1, errors


def test_seam_ratio_known_answers(atlas):
    """A texture baked from a smooth function of position is about as continuous across seams as along edges
    (ratio about 1); random texels, which ignore the surface, differ across seams as much as between any two texels
    of a chart's border (ratio well above)."""
    from dpi.evaluation.seams import seam_pairs, seam_ratio

    mesh, _ = atlas
    assert len(seam_pairs(mesh.vertices, mesh.uvs)) > 20
    smooth = bake(mesh, colour_field, 128)
    assert seam_ratio(mesh.vertices, mesh.faces, mesh.uvs, smooth) < 1.5
    from scipy.ndimage import gaussian_filter

    chart_noise = np.random.default_rng(0).uniform(0, 1, (128, 128, 3))
    blurred = gaussian_filter(chart_noise, (3, 3, 0))  # smooth inside a chart, unrelated across charts
    assert seam_ratio(mesh.vertices, mesh.faces, mesh.uvs, blurred) > 1.5


def test_fill_gutters_copies_the_nearest_chart_texel(atlas):
    mesh, _ = atlas
    covered = chart_texels(mesh.uvs, mesh.faces, 128)
    texture = np.zeros((128, 128, 1))
    texture[covered] = 1.0
    filled = fill_gutters(texture, covered)
    assert (filled == 1.0).all() and 0.3 < covered.mean() < 1.0


def test_seam_ties_join_both_sides_of_each_seam(atlas):
    """Tying a texture blurred inside its charts (unrelated across them) makes its seams nearly as continuous as a
    texture baked from the surface, and the tied texels of a group equal their former mean."""
    import torch
    from scipy.ndimage import gaussian_filter

    from dpi.evaluation.seams import seam_ratio
    from dpi.solve.seams import SeamTies

    mesh, _ = atlas
    ties = SeamTies.of_mesh(mesh.vertices, mesh.faces, mesh.uvs, 128)
    assert ties.count > 10 and len(ties.texels) > ties.count
    texture = gaussian_filter(np.random.default_rng(0).uniform(0, 1, (128, 128, 3)), (3, 3, 0))
    tied = ties.tie_(torch.from_numpy(texture.copy())).numpy()
    group = ties.texels[ties.groups == 0].numpy()
    mean = texture.reshape(-1, 3)[group].mean(0)
    np.testing.assert_allclose(tied.reshape(-1, 3)[group], np.broadcast_to(mean, (len(group), 3)))
    before = seam_ratio(mesh.vertices, mesh.faces, mesh.uvs, texture)
    after = seam_ratio(mesh.vertices, mesh.faces, mesh.uvs, tied)
    assert after < 0.6 * before


def test_seam_ties_of_a_sphere_grid_join_the_wrap_columns():
    """The blob's parametric UVs meet at u = 0 and u = 1: texels of the first and last column of a row are tied."""
    import torch

    from dpi.solve.seams import SeamTies

    shape = blob(resolution=8, seed=1)
    ties = SeamTies.of_mesh(shape.vertices, shape.faces, shape.uvs, 16)
    texture = torch.zeros(16, 16, 1)
    texture[:, 0] = 1.0
    ties.tie_(texture)
    assert torch.allclose(texture[4:12, 0], texture[4:12, -1]) and float(texture[8, 0]) == 0.5


def test_a_mesh_far_denser_than_its_texture_is_simplified_before_the_atlas():
    """14,000 faces for 32 x 32 texels: quadric edge collapse to one face per texel, the shape kept."""
    import trimesh

    shape = blob(resolution=60, seed=2)
    merged = trimesh.Trimesh(shape.vertices, shape.faces, process=False)
    merged.merge_vertices()
    mesh, summary = uv_atlas(np.asarray(merged.vertices), np.asarray(merged.faces), 32)
    assert summary["given_faces"] > 10000 and 900 <= summary["faces"] <= 1024 + 8
    np.testing.assert_allclose(np.ptp(mesh.vertices, 0), np.ptp(np.asarray(merged.vertices), 0), rtol=0.03)
    _, small = uv_atlas(np.asarray(merged.vertices), np.asarray(merged.faces), 128)
    assert small["faces"] == small["given_faces"]  # dense enough for 128 x 128: kept as it is


@pytest.mark.parametrize("damage", ["triangle soup", "doubled faces"])
def test_a_scanners_soup_or_doubled_faces_are_simplified_like_a_clean_mesh(damage):
    import trimesh

    from dpi.preprocess.uv import FACES_PER_TEXEL, simplified_for_texture

    sphere = trimesh.creation.icosphere(subdivisions=4)  # 5120 faces
    vertices, faces = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    if damage == "triangle soup":  # every face with its own three vertices (an STL's)
        vertices, faces = vertices[faces].reshape(-1, 3), np.arange(3 * len(faces)).reshape(-1, 3)
    else:
        faces = np.concatenate([faces, faces[:, ::-1]])
    _, simplified = simplified_for_texture(vertices, faces, 16)
    assert len(simplified) <= FACES_PER_TEXEL * 16 * 16


def test_a_mesh_that_cannot_be_simplified_says_so(caplog):
    from dpi.preprocess.uv import simplified_for_texture

    rng = np.random.default_rng(0)
    corners = rng.normal(size=(2000, 1, 3)) * 10 + rng.normal(scale=0.01, size=(2000, 3, 3))  # 2000 lone specks
    vertices, faces = corners.reshape(-1, 3), np.arange(6000).reshape(-1, 3)
    with caplog.at_level("WARNING", logger="dpi.preprocess.uv"):
        _, kept = simplified_for_texture(vertices, faces, 8)
    assert len(kept) > 128 and "charts are smaller than a texel" in caplog.text
