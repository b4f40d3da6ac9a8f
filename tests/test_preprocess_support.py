"""The support the object stands on, from which sparse points every camera sees: a table reaching out of the frames is
cut at its top, a floor far below a floating object cuts nothing of it, and no support is none."""

import numpy as np
import pytest

from dpi.capture.cameras import from_fov, orbit
from dpi.preprocess.depth_seeds import SUPPORT_TOLERANCE, between_cameras, support_height
from dpi.preprocess.hull import visible_sphere
from dpi.preprocess.sfm import in_view_fraction

UP = np.array([0.0, 1.0, 0.0])


@pytest.fixture(scope="module", params=[360.0, 180.0])
def cameras(request):
    return [from_fov(c2w, 120, 120, 40.0, f"v{i}")
            for i, c2w in enumerate(orbit(16, 4.0, (15.0, 30.0), arc_deg=request.param))]


def ball(count: int, radius: float, seed: int = 0) -> np.ndarray:
    p = np.random.default_rng(seed).normal(size=(count, 3))
    return radius * p / np.linalg.norm(p, axis=1, keepdims=True)


def disc(count: int, height: float, radius: float, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    r, angle = radius * np.sqrt(rng.uniform(size=count)), rng.uniform(0, 2 * np.pi, count)
    return np.stack([r * np.cos(angle), np.full(count, height), r * np.sin(angle)], axis=1)


def plane_above(cameras, points: np.ndarray) -> float | None:
    """The support plane's height less its tolerance (the support's top point), None without one."""
    centre, radius = visible_sphere(cameras)
    height = support_height(points, cameras, UP, centre, radius)
    distance = np.mean([np.linalg.norm(c.center - centre) for c in cameras])
    return None if height is None else height - SUPPORT_TOLERANCE * distance


def test_a_table_reaching_out_of_the_frames_is_cut_at_its_top(cameras):
    table = disc(2000, -0.5, 3.0)
    assert (in_view_fraction(table, cameras) < 1).any() and (in_view_fraction(table, cameras) == 1).any()
    top = plane_above(cameras, np.concatenate([ball(300, 0.5), table]))
    assert top == pytest.approx(-0.5, abs=0.05)


def test_a_floor_far_below_a_floating_object_cuts_nothing_of_it(cameras):
    floor = disc(2000, -2.5, 4.0)
    top = plane_above(cameras, np.concatenate([ball(300, 0.5), floor]))
    assert top == pytest.approx(-2.5, abs=0.05)


def test_an_object_seen_whole_with_nothing_under_it_has_no_support(cameras):
    assert plane_above(cameras, ball(300, 0.5)) is None


def test_a_domed_table_is_cut_above_its_part_in_every_frame(cameras):
    table = disc(4000, -0.5, 3.0)
    table[:, 1] += 0.03 * (1 - np.linalg.norm(table[:, [0, 2]], axis=1) / 3.0)  # higher near the object's foot
    shared = in_view_fraction(table, cameras) == 1
    top = plane_above(cameras, np.concatenate([ball(300, 0.5) + [0, 0.03, 0], table]))
    assert top >= np.quantile(table[shared, 1], 0.01) - 1e-9


def test_a_wall_close_behind_a_half_circle_capture_is_not_its_support():
    cameras = [from_fov(c2w, 120, 120, 40.0, f"v{i}") for i, c2w in enumerate(orbit(16, 4.0, (15.0, 30.0),
                                                                                       arc_deg=180.0))]
    rng = np.random.default_rng(2)
    wall = np.stack([np.full(3000, -1.2), rng.uniform(-2.5, 3.0, 3000), rng.uniform(-4.0, 4.0, 3000)], axis=1)
    floor = disc(2000, -2.5, 4.0)
    front = floor[floor[:, 0] > -1.2]  # the floor ends at the wall; the arc's middle is +x
    assert not between_cameras(wall, cameras, UP).any() and between_cameras(front, cameras, UP).mean() > 0.3
    top = plane_above(cameras, np.concatenate([ball(300, 0.5), front, wall]))
    assert top == pytest.approx(-2.5, abs=0.05)
