"""Outdoor env-map generator: scene kinds, street ray casting and shading, daylight, true HDR suns."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dpi.io.images import luminance
from dpi.light.envmap import direction_to_texel, texel_solid_angles
from dpi.light.sunlight import draw_sun_np
from dpi.worlds.daylight import (Daylight, irradiance, overcast, physical_daylight, random_sun_elevation,
                                 upper_hemisphere)
from dpi.worlds.families import check_envmap
from dpi.worlds.outdoor import SCENE_KINDS, landscape_envmap, outdoor_envmap
from dpi.worlds.skies import SkyParams, sun_direction, sunsky_envmap
from dpi.worlds.street import FACADE, GROUND, Facades, Street, cast, occluded, street_envmap

UP = np.array([[0.0, 1.0, 0.0]])


def wall(offset: float, height: float, albedo: float = 0.4) -> Facades:
    """One plain (windowless) building front 600 m long at v = offset."""
    one = np.ones(1)
    return Facades(offset=offset, edges=np.array([-300.0, 300.0]), heights=one * height, albedo=np.full((1, 3), albedo),
                   window_fraction=0 * one, window_f0=0 * one, storey=3 * one, bay=3 * one)


def street(rows: list[Facades], vehicles: tuple[list, list] = ([], [])) -> Street:
    """A street along azimuth 0 (+u = -Z, +v = +X), eye 1.7 m up, ground of one albedo (0.1) everywhere."""
    grey = np.full(3, 0.1)
    return Street(azimuth=0.0, eye_height=1.7, road=(-9.0, 9.0), lanes=1, building_lines=(-12.0, 10.0), rows=rows,
                  vehicles_lo=np.reshape(vehicles[0], (-1, 3)), vehicles_hi=np.reshape(vehicles[1], (-1, 3)),
                  vehicle_albedo=np.full((len(vehicles[0]), 3), 0.3), asphalt=grey, pavement=grey)


def uniform_daylight(height: int, elevation: float, azimuth: float, sun: float = 100.0) -> Daylight:
    """A sky of radiance 1 everywhere above the horizon and a sun of irradiance `sun` (grey)."""
    return Daylight(sky=np.ones((height, 2 * height, 3)) * upper_hemisphere(height)[..., None],
                    sun=sun_direction(elevation, azimuth), sun_irradiance=np.full(3, sun))


def texel(env: np.ndarray, elevation: float, azimuth: float) -> np.ndarray:
    """RGB of the texel a direction at (elevation, azimuth) in degrees falls into."""
    return env[direction_to_texel(sun_direction(elevation, azimuth), env.shape[0])]


def top_energy_share(env: np.ndarray, fraction: float = 0.005) -> float:
    """Share of the energy (luminance x solid angle) in the brightest `fraction` of texels."""
    lum = luminance(env.astype(np.float64))
    energy = (lum * texel_solid_angles(env.shape[0])).ravel()
    top = np.argsort(lum.ravel())[-max(1, int(round(fraction * lum.size))):]
    return float(energy[top].sum() / energy.sum())


@pytest.mark.parametrize("kind", sorted(SCENE_KINDS))
def test_each_kind_is_valid_and_seeded(kind: str) -> None:
    a = outdoor_envmap(16, np.random.default_rng(5), kind=kind)
    assert np.array_equal(a, outdoor_envmap(16, np.random.default_rng(5), kind=kind))
    assert not np.array_equal(a, outdoor_envmap(16, np.random.default_rng(6), kind=kind))
    check_envmap(a, 16)
    assert luminance(a[:8]).min() > 0  # no black sky texel


def test_unknown_kind_is_an_error() -> None:
    with pytest.raises(ValueError, match="kind"):
        outdoor_envmap(8, np.random.default_rng(0), kind="underwater")


def test_sun_elevations_cover_low_and_high_suns() -> None:
    rng = np.random.default_rng(0)
    elevations = np.array([random_sun_elevation(rng) for _ in range(4000)])
    assert elevations.min() >= 0.5 and elevations.max() <= 80.0 and elevations.max() > 75.0
    assert np.mean(elevations < 10.0) == pytest.approx(0.3, abs=0.03)


def test_rays_hit_the_nearest_surface() -> None:
    s = street([wall(10.0, 8.0), wall(30.0, 60.0)], vehicles=([[5.0, -1.0, 0.0]], [[9.0, 1.0, 1.5]]))
    dirs = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, -1.0], [1.0, 0.0, -0.1]])
    hits = cast(s, dirs / np.linalg.norm(dirs, axis=1, keepdims=True))
    assert list(hits.surface) == [FACADE, FACADE, GROUND, 3]
    assert list(hits.index[:2]) == [0, 1]  # over the 8 m wall, the 45-degree ray meets the back row at 30 m
    assert hits.points[1] == pytest.approx([0.0, 30.0, 31.7])
    assert hits.points[3] == pytest.approx([5.0, 0.0, 1.2])  # the vehicle's rear face, facing backwards
    assert list(hits.normal) == [4, 4, 0, 2]


def test_shadow_rays_are_blocked_by_walls_and_vehicles() -> None:
    s = street([wall(10.0, 8.0)], vehicles=([[-2.0, -6.0, 0.0]], [[2.0, -4.0, 1.5]]))
    sun = np.array([0.0, 1.0, 1.0]) / np.sqrt(2)  # 45 degrees up, towards +v
    points = np.array([[0.0, 3.0, 0.0], [0.0, 1.0, 0.0], [0.0, -7.0, 0.0], [0.0, -9.0, 0.0]])
    assert list(occluded(s, points, np.broadcast_to(sun, points.shape))) == [True, False, True, False]


def test_sunlit_facade_gains_its_albedo_times_the_sun() -> None:
    s = street([wall(10.0, 30.0, albedo=0.4)])
    facing = street_envmap(uniform_daylight(32, 30.0, 270.0), s)  # sun behind the eye, on the facade
    behind = street_envmap(uniform_daylight(32, 30.0, 90.0), s)  # sun behind the building
    gain = texel(facing, 8.0, 90.0) - texel(behind, 8.0, 90.0)
    assert gain == pytest.approx(0.4 * 100.0 * np.cos(np.radians(30.0)) / np.pi, rel=0.1)


def test_shadowed_road_is_darker_than_sunlit_road() -> None:
    env = street_envmap(uniform_daylight(32, 45.0, 90.0), street([wall(10.0, 8.0)]))
    shadowed, sunlit = texel(env, -14.0, 90.0), texel(env, -14.0, 270.0)  # ground 6.8 m either side of the eye
    assert sunlit - shadowed == pytest.approx(0.1 * 100.0 * np.sin(np.radians(45.0)) / np.pi, rel=0.1)


def test_sun_has_the_sunsky_power_unless_a_facade_hides_it() -> None:
    params = SkyParams(sun_elevation_deg=30.0, sun_azimuth_deg=90.0, turbidity=3.0, supersample=1)
    light = physical_daylight(32, params)
    row, col = direction_to_texel(light.sun, 32)
    deposit = sunsky_envmap(32, params)[row, col] - sunsky_envmap(32, replace(params, sun_scale=0.0))[row, col]
    open_side = street_envmap(light, street([wall(-10.0, 30.0)]))
    drawn = draw_sun_np(light.sun, light.sun_irradiance, 32)  # its disc and aureole, energy sunsky's deposit
    assert (drawn * texel_solid_angles(32)[..., None]).sum((0, 1)) == pytest.approx(
        deposit * texel_solid_angles(32)[row, 0], rel=1e-4)
    assert open_side[row, col] - light.sky[row, col] == pytest.approx(drawn[row, col], rel=1e-4)
    hidden = street_envmap(light, street([wall(10.0, 30.0)]))
    assert luminance(hidden[row, col]) < 1e-3 * luminance(deposit)


def test_overcast_spreads_the_total_irradiance_and_hides_the_sun() -> None:
    clear = physical_daylight(16, SkyParams(sun_elevation_deg=40.0, turbidity=3.0, supersample=1))
    cloudy = overcast(clear, np.random.default_rng(0), transmittance=0.4)
    total = irradiance(clear.sky, UP)[0] + clear.sun_irradiance * clear.sun[1]
    assert luminance(irradiance(cloudy.sky, UP)[0]) == pytest.approx(0.4 * luminance(total), rel=1e-9)
    assert not cloudy.sun_irradiance.any()
    for seed in range(4):
        lum = luminance(outdoor_envmap(16, np.random.default_rng(seed), kind="overcast"))
        assert lum.max() / np.median(lum) < 100  # clear skies reach 1e3-1e4


def test_clear_landscape_energy_is_dominated_by_the_sun() -> None:
    params = SkyParams(sun_elevation_deg=40.0, turbidity=3.0, supersample=1)
    light = physical_daylight(32, params)
    row, col = direction_to_texel(light.sun, 32)
    physical = {albedo: sunsky_envmap(32, replace(params, ground_albedo=albedo))
                for albedo in (0.04, 0.8)}
    drawn = draw_sun_np(light.sun, light.sun_irradiance, 32)[row, col]
    for seed in range(3):
        env = landscape_envmap(light, np.random.default_rng(seed))
        assert env[row, col] - light.sky[row, col] == pytest.approx(drawn, rel=1e-4)
        # the ground albedo (0.05-0.8) brackets the sun's share of the energy, as in the physical model
        assert 0.9 * top_energy_share(physical[0.8]) < top_energy_share(env) < 1.1 * top_energy_share(physical[0.04])
    assert top_energy_share(physical[0.8]) > 0.3
