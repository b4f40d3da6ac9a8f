"""Indoor generator: known answers of the analytic room renderer (direct light, shadows, emitters, smoothness)."""

from __future__ import annotations

import numpy as np
import pytest

from dpi.io.images import luminance
from dpi.worlds.families import check_envmap
from dpi.worlds.indoor import (RectEmitter, Room, SpotLight, cast_rays, direct_irradiance, indoor_envmaps,
                               rect_irradiance, render_room, window_texture)
from dpi.worlds.raycast import subtexel_directions

SIZE = np.array([6.0, 3.0, 6.0])
X, Y, Z = np.eye(3)


def ceiling_panel(half: float, radiance: float | list[float]) -> RectEmitter:
    """A uniform square panel facing down just under the centre of the test room's ceiling."""
    centre = np.array([3.0, SIZE[1] - 1e-3, 3.0])
    return RectEmitter(centre, X, Z, half, half, np.broadcast_to(np.asarray(radiance, float), 3)[None, None])


def bare_room(emitters: tuple[RectEmitter, ...] = (), spots: tuple[SpotLight, ...] = (),
              boxes: tuple[tuple[list[float], list[float]], ...] = (), eye: tuple[float, ...] = (3.0, 1.5, 3.0),
              ) -> Room:
    """The 6 x 3 x 6 m test room, all surfaces of albedo 0.5, with the given lights and boxes [lo, hi]."""
    lo = np.array([b[0] for b in boxes], float).reshape(-1, 3)
    hi = np.array([b[1] for b in boxes], float).reshape(-1, 3)
    return Room(SIZE, np.full((6, 3), 0.5), lo, hi, np.full((len(boxes), 3), 0.5), emitters, spots, np.array(eye))


def corner_form_factor(a: float, b: float, h: float) -> float:
    """Form factor from a point to an a x b rectangle parallel to its surface at height h, above one corner."""
    x, y = a / h, b / h
    return (x / np.sqrt(1 + x * x) * np.arctan(y / np.sqrt(1 + x * x))
            + y / np.sqrt(1 + y * y) * np.arctan(x / np.sqrt(1 + y * y))) / (2 * np.pi)


FLOOR_UP = np.array([[0.0, 1.0, 0.0]])


@pytest.mark.parametrize("point, corners", [((3.0, 0.0, 3.0), 4), ((2.5, 0.0, 2.5), 1)])
def test_floor_irradiance_under_a_panel_matches_the_form_factor(point: tuple[float, ...], corners: int) -> None:
    panel = ceiling_panel(0.5, 1.0)
    h = SIZE[1] - 1e-3
    # Below the centre: four 0.5 x 0.5 corner rectangles; below a corner: one 1 x 1 rectangle.
    exact = np.pi * (4 * corner_form_factor(0.5, 0.5, h) if corners == 4 else corner_form_factor(1.0, 1.0, h))
    room = bare_room((panel,))
    default = rect_irradiance(room, np.array([point]), FLOOR_UP, panel)[0, 0]
    fine = rect_irradiance(room, np.array([point]), FLOOR_UP, panel, n=32)[0, 0]
    assert default == pytest.approx(exact, rel=1e-3)
    assert fine == pytest.approx(exact, rel=1e-3)


def test_direct_light_conserves_the_emitted_flux() -> None:
    panel = ceiling_panel(0.5, 1.0)
    room = bare_room((panel,))
    flux = 0.0
    for face in range(6):  # integrate the irradiance over every face of the closed room on a midpoint grid
        axis, far = divmod(face, 2)
        a, b = [k for k in range(3) if k != axis]
        grid = (np.arange(40) + 0.5) / 40
        points = np.zeros((40, 40, 3))
        points[..., a], points[..., b] = np.meshgrid(grid * SIZE[a], grid * SIZE[b], indexing="ij")
        points[..., axis] = SIZE[axis] * far
        normals = np.zeros_like(points)
        normals[..., axis] = -1.0 if far else 1.0
        flux += direct_irradiance(room, points.reshape(-1, 3), normals.reshape(-1, 3))[:, 0].mean() * SIZE[a] * SIZE[b]
    assert flux == pytest.approx(panel.power[0], rel=0.01)


def test_a_box_between_panel_and_floor_casts_a_shadow() -> None:
    panel = ceiling_panel(0.3, 10.0)
    shadowed = bare_room((panel,), boxes=(([2.5, 1.0, 2.5], [3.5, 1.5, 3.5]),))
    points = np.array([[3.0, 0.0, 3.0], [3.0, 0.0, 3.2], [1.0, 0.0, 1.0]])
    normals = np.repeat(FLOOR_UP, 3, axis=0)
    lit = direct_irradiance(bare_room((panel,)), points, normals)[:, 0]
    dark = direct_irradiance(shadowed, points, normals)[:, 0]
    assert (lit > 0).all()
    assert dark[0] == 0 and dark[1] == 0  # umbra under the box
    assert dark[2] == pytest.approx(lit[2])  # the box is not between the panel and this point


def test_spot_light_lights_its_cone_only() -> None:
    spot = SpotLight(np.array([3.0, 2.9, 3.0]), -Y, np.array([20.0, 10.0, 5.0]), np.radians(30))
    room = bare_room(spots=(spot,))
    points = np.array([[3.0, 0.0, 3.0], [3.0 + 2.9 * np.tan(np.radians(35)), 0.0, 3.0]])
    irradiance = direct_irradiance(room, points, np.repeat(FLOOR_UP, 2, axis=0))
    assert irradiance[0] == pytest.approx(spot.intensity / 2.9**2, rel=1e-4)  # on the axis: I / r^2
    assert (irradiance[1] == 0).all()  # outside the cutoff angle


def test_an_emitter_seen_straight_on_shows_its_radiance_exactly() -> None:
    radiance = [500.0, 400.0, 300.0]
    env = render_room(bare_room((ceiling_panel(1.5, radiance),)), 32)
    # Rows 0-4 (polar angle < 28 deg) lie inside the panel's +-45 deg seen from 1.5 m below its centre.
    np.testing.assert_allclose(env[:5], np.broadcast_to(radiance, env[:5].shape), rtol=1e-6)


def test_window_texture_is_upright_and_faces_out() -> None:
    sky, ground = [8.0, 9.0, 10.0], [1.0, 0.8, 0.5]
    texture = np.array([[sky], [ground]])  # row 0 is the top edge
    window = RectEmitter(np.array([SIZE[0] - 1e-3, 1.5, 3.0]), Z, Y, 2.0, 1.0, texture)  # on the +x wall, facing -x
    env = render_room(bare_room((window,)), 32)
    # +x is azimuth 90 deg: columns 15 and 16 of 64; row 15 looks just above the horizon, row 16 just below.
    np.testing.assert_allclose(env[15, 15:17], [sky, sky], rtol=1e-6)
    np.testing.assert_allclose(env[16, 15:17], [ground, ground], rtol=1e-6)
    band = np.arange(32, dtype=float)[None, :, None].repeat(8, 0).repeat(3, 2)  # texel value = its column
    crop = window_texture(band, -X, np.random.default_rng(0))  # a window on the x = 0 wall looks out to -x
    assert abs(crop[0, 4, 0] - 24) <= 2  # azimuth 270 deg is column 24 of 32


def test_lit_wall_is_smooth_and_rendering_is_deterministic() -> None:
    room = bare_room((ceiling_panel(0.5, 20.0),))
    env = render_room(room, 32)
    assert np.array_equal(env, render_room(room, 32))
    lum = luminance(env)
    surface = cast_rays(room, subtexel_directions(32, 1).reshape(-1, 3)).surface.reshape(32, 64)
    for row in (14, 18):
        same = (surface[row, :-2] == surface[row, 1:-1]) & (surface[row, 1:-1] == surface[row, 2:])
        l = lum[row]
        second = np.abs(l[:-2] - 2 * l[1:-1] + l[2:])[same] / l[1:-1][same]
        assert same.sum() > 30 and second.max() < 0.05  # measured 0.02 (32-spp path tracing: median 0.78)


def test_indoor_maps_are_valid_and_seeded() -> None:
    maps = indoor_envmaps(8, np.random.default_rng(0), 3)
    assert maps.shape == (3, 8, 16, 3) and maps.dtype == np.float32
    for env in maps:
        check_envmap(env, 8)
        assert (env > 0).all()
    assert np.array_equal(maps, indoor_envmaps(8, np.random.default_rng(0), 3))
    assert not np.array_equal(maps[0], maps[1])
