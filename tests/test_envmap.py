"""Equirect conventions against Mitsuba's envmap emitter, padding, and the sunsky rotation."""

import numpy as np
import pytest
import torch

from dpi.light.envmap import (direction_to_texel, pad_equirect, pad_for_mitsuba, texel_directions, texel_solid_angles,
                              top_energy_share, unpad_from_mitsuba)


def eval_emitter(mi, emitter, directions):
    import drjit as dr

    si = dr.zeros(mi.SurfaceInteraction3f, len(directions))
    si.wi = mi.Vector3f(*(-directions.T.astype(np.float32)))
    return np.array(emitter.eval(si)).T


def test_texel_directions_round_trip():
    rows, cols = direction_to_texel(texel_directions(8), 8)
    assert (rows == np.arange(8)[:, None]).all() and (cols == np.arange(16)[None, :]).all()


def test_solid_angles_cover_the_sphere():
    assert texel_solid_angles(16).sum() * 32 == pytest.approx(4 * np.pi)


def test_bright_texels_are_where_mitsuba_sees_them(mi):
    env = np.zeros((8, 16, 3), np.float32)
    env[2, 5] = 100.0
    env[6, 13] = 50.0
    emitter = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(env)})
    values = eval_emitter(mi, emitter, texel_directions(8).reshape(-1, 3))[:, 0].reshape(8, 16)
    assert np.unravel_index(values.argmax(), values.shape) == (2, 5)
    assert values[6, 13] > 10 * np.median(values)


def test_padding_matches_mitsubas_own_data_layout(mi):
    env = np.random.default_rng(0).random((8, 16, 3)).astype(np.float32)
    params = mi.traverse(mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(env)}))
    data = np.array(params["data"])
    padded = pad_for_mitsuba(torch.from_numpy(env), data.shape[1]).numpy()
    np.testing.assert_allclose(padded, data, rtol=1e-6)
    np.testing.assert_array_equal(unpad_from_mitsuba(padded, 16), env)


@pytest.mark.parametrize("extra", [0, 1, 2])
def test_padding_layouts(extra):
    env = torch.arange(2 * 4 * 3, dtype=torch.float32).reshape(2, 4, 3)
    padded = pad_for_mitsuba(env, 4 + extra)
    assert padded.shape[1] == 4 + extra
    assert torch.equal(torch.from_numpy(unpad_from_mitsuba(padded.numpy(), 4)), env)
    if extra:
        assert torch.equal(padded[:, -1], env[:, 0])


def test_sunsky_sun_lands_in_its_texel_with_ground_below(mi):
    from dpi.worlds.skies import SkyParams, sun_direction, sunsky_envmap

    env = sunsky_envmap(16, SkyParams(sun_elevation_deg=30.0, sun_azimuth_deg=100.0))
    assert env.shape == (16, 32, 3) and np.isfinite(env).all() and (env >= 0).all()
    row, col = direction_to_texel(sun_direction(30.0, 100.0), 16)
    assert np.unravel_index(env[..., 0].argmax(), env.shape[:2]) == (row, col)
    assert row < 8  # sun above the horizon in the +Y-up map
    ground = env[8:].mean()
    assert 0 < ground < env[:8].mean()


def test_equirect_padding_wraps_azimuth_and_crosses_the_poles():
    env = torch.arange(2 * 3 * 6, dtype=torch.float32).reshape(1, 2, 3, 6)
    padded = pad_equirect(env, 1)
    assert padded.shape == (1, 2, 5, 8)
    inner = padded[..., 1:-1]
    torch.testing.assert_close(padded[..., 1:-1, 0], env[..., -1])  # left of column 0: the last column
    torch.testing.assert_close(inner[..., 0, :], torch.roll(env[..., 0, :], 3, dims=-1))  # over the north pole
    torch.testing.assert_close(inner[..., -1, :], torch.roll(env[..., -1, :], 3, dims=-1))  # under the south pole


def test_top_energy_share_is_one_for_a_point_light_and_near_the_fraction_for_a_uniform_map():
    """A single bright texel holds all of a black map's energy; a uniform map's brightest 1 % (its largest texels,
    at the equator) hold 1 % to pi / 2 % of it."""
    def peak_share(env):
        return top_energy_share(env, 0.01)

    point = np.zeros((32, 64, 3), np.float32)
    point[10, 20] = 50.0
    assert peak_share(point) == pytest.approx(1.0)
    uniform = np.ones_like(point)
    assert 0.01 <= peak_share(uniform) <= 0.01 * np.pi / 2
    sky = uniform.copy()
    sky[:16] *= 10.0  # a bright upper half: its largest texels hold more than a uniform map's
    assert peak_share(sky) > peak_share(uniform)
