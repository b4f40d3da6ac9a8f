"""Property tests: tone curve, env-map directions and camera conversions round-trip for any input."""

import numpy as np
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from dpi.capture.cameras import Camera, look_at, read_transforms, write_transforms
from dpi.light.envmap import direction_to_texel, directions_from_angles, texel_directions
from dpi.light.tonecurve import TONE_CURVES, LogEncoding

finite = st.floats(min_value=-50, max_value=50, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(curve=st.sampled_from([*TONE_CURVES.values(), LogEncoding()]), scale=st.floats(1e-4, 1e4),
       x=st.lists(st.floats(-1, 1, allow_nan=False), min_size=1, max_size=16))
def test_encoding_inverse_round_trips(curve, scale, x):
    curve = curve.with_scale(scale)
    x = torch.tensor(x, dtype=torch.float64)
    radiance = curve.to_radiance(x)
    assert torch.isfinite(radiance).all() and (radiance >= 0).all()
    torch.testing.assert_close(curve.to_prior(radiance), x, atol=1e-9, rtol=0)


@settings(max_examples=60, deadline=None)
@given(theta=st.floats(0.001, np.pi - 0.001), phi=st.floats(0, 2 * np.pi - 1e-6), height=st.integers(2, 64))
def test_direction_texel_consistency(theta, phi, height):
    d = directions_from_angles(np.array(theta), np.array(phi))
    assert np.isclose(np.linalg.norm(d), 1.0)
    row, col = direction_to_texel(d, height)
    centre = texel_directions(height)[row, col]
    # the texel centre is within one texel's angular size of the direction
    assert np.degrees(np.arccos(np.clip(centre @ d, -1, 1))) <= 180.0 / height * 1.5 + 1e-9


@settings(max_examples=40, deadline=None)
@given(origin=st.tuples(finite, finite, finite), target=st.tuples(finite, finite, finite),
       fx=st.floats(1, 1e4), cx=st.floats(0, 512), cy=st.floats(0, 512))
def test_camera_transforms_round_trip(origin, target, fx, cx, cy):
    o, t = np.array(origin), np.array(target)
    forward = t - o
    if np.linalg.norm(forward) < 1e-3 or np.linalg.norm(np.cross(forward, [0, 1, 0])) < 1e-3 * np.linalg.norm(forward):
        return  # degenerate look-at (no direction, or looking straight up/down)
    cam = Camera(look_at(o, t), 512, 384, fx, fx, cx, cy, "v")
    (_, back), = read_transforms(write_transforms([("images/v.png", cam)]))
    np.testing.assert_allclose(back.c2w, cam.c2w)
    R = back.c2w[:3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-9)
