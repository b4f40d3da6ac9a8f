"""What a mirror's views pin down stays as the init fitted it (dpi.solve.dps.loop.seen_weight,
keep_what_the_views_see): known answers on a mirror-like and a rough transport, and the blend's limits."""

import torch

from dpi.solve.dps.loop import keep_what_the_views_see, seen_weight

HEIGHT = 16
TEXELS = HEIGHT * 2 * HEIGHT


def test_a_mirror_pins_the_texels_it_reflects_and_leaves_the_rest():
    """Each pixel sees one texel (a mirror): seen texels get s / (s + median) = 1/2 at even coverage, unseen 0."""
    weights = torch.zeros(12, TEXELS)
    seen = torch.arange(12) % 6  # pixels reflect texels 0-5, two pixels each
    weights[torch.arange(12), seen] = 1.0
    weight = seen_weight(weights, HEIGHT).flatten()
    assert torch.allclose(weight[:6], torch.full((6,), 0.5)) and (weight[6:] == 0).all()


def test_on_a_grid_as_coarse_as_a_lobe_nothing_is_pinned():
    """The same one-texel pixels on a 4-row grid see a texel of 0.4 sr, a rough lobe's size: nothing is pinned."""
    weights = torch.zeros(12, 32)
    weights[torch.arange(12), torch.arange(12) % 6] = 1.0
    assert (seen_weight(weights, 4) == 0).all()


def test_a_rough_object_pins_nothing():
    """Each pixel sees a wide lobe of texels alike (a rough object): nothing is pinned."""
    weights = torch.rand(20, TEXELS, generator=torch.Generator().manual_seed(0)) + 1.0
    assert (seen_weight(weights, HEIGHT) == 0).all()


def test_the_blend_keeps_the_sample_unpinned_and_the_init_where_pinned():
    generator = torch.Generator().manual_seed(1)
    env, init = (torch.rand(32, 64, 3, generator=generator) + 0.1 for _ in range(2))
    assert torch.equal(keep_what_the_views_see(env, init, torch.zeros(HEIGHT, 2 * HEIGHT)), env)
    assert torch.allclose(keep_what_the_views_see(env, init, torch.ones(HEIGHT, 2 * HEIGHT)), init, rtol=1e-5)


def test_the_unpinned_sample_is_brought_to_the_inits_level():
    """Where the init is the sample times 4 everywhere, half-pinned texels and free ones alike end at the init."""
    env = torch.rand(32, 64, 3, generator=torch.Generator().manual_seed(2)) + 0.1
    weight = torch.zeros(HEIGHT, 2 * HEIGHT)
    weight[:, :HEIGHT] = 0.5
    assert torch.allclose(keep_what_the_views_see(env, 4 * env, weight), 4 * env, rtol=1e-5)
