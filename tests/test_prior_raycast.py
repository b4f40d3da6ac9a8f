"""The procedural worlds' one raycaster: sub-texel rays of equal solid angle, texel means, box slab tests."""

import numpy as np

from dpi.worlds.raycast import slabs, subtexel_directions, texel_mean


def test_subtexel_rays_are_unit_and_inside_their_texel():
    dirs = subtexel_directions(8, 3)
    assert dirs.shape == (8, 16, 9, 3) and np.allclose(np.linalg.norm(dirs, axis=-1), 1)
    theta = np.arccos(np.clip(dirs[..., 1], -1, 1))  # +Y up: the polar angle from the zenith
    rows = np.floor(theta / np.pi * 8).astype(int)
    assert (rows == np.arange(8)[:, None, None]).all()


def test_texel_mean_of_a_constant_and_of_the_rays_own_index():
    n, height = 2, 4
    values = np.arange(height * 2 * height * n * n, dtype=float)
    means = texel_mean(values, height, n)
    assert means.shape == (height, 2 * height)
    assert np.allclose(means.ravel(), np.arange(height * 2 * height) * n * n + (n * n - 1) / 2)
    assert np.allclose(texel_mean(np.ones((height * 2 * height * n * n, 3)), height, n), 1)


def test_slab_test_known_answers_and_broadcasting():
    origins = np.array([[-2.0, 0.5, 0.5], [0.5, 0.5, -3.0], [0.5, 5.0, 0.5]])
    dirs = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    entry, exit_, near_axis, far_axis = slabs(origins, dirs, np.zeros(3), np.ones(3))
    assert np.allclose(entry[:2], [2.0, 3.0]) and np.allclose(exit_[:2], [3.0, 4.0])
    assert list(near_axis[:2]) == [0, 2] and list(far_axis[:2]) == [0, 2]
    assert entry[2] > exit_[2]  # passes above the box
    boxes_lo, boxes_hi = np.array([[0.0, 0, 0], [5.0, 0, 0]]), np.array([[1.0, 1, 1], [6.0, 1, 1]])
    entry, exit_, _, _ = slabs(origins[None, :1], dirs[None, :1], boxes_lo[:, None], boxes_hi[:, None])
    assert entry.shape == (2, 1) and np.allclose(entry[:, 0], [2.0, 7.0])


def test_rays_split_each_texel_into_equal_solid_angles():
    """Sub-rays sit at the midpoints of equal cos(theta) steps, so their mean height is the texel's exact mean
    cos(theta), which rays spaced evenly in theta would miss."""
    height = 8
    dirs = subtexel_directions(height, 4)
    edges = np.cos(np.arange(height + 1) / height * np.pi)
    assert np.allclose(dirs[..., 1].mean(axis=(1, 2)), (edges[:-1] + edges[1:]) / 2)
