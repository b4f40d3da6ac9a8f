"""benchmarks/lobe_views.py's blocks: each texel's block, and the albedo a pixel sees per unit factor of a block."""

import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
from lobe_views import BLOCK, block_index, block_operator  # noqa: E402

from dpi.solve.transport import AlbedoLookup  # noqa: E402


class Recorded:
    """What block_operator reads of a transport: its albedo lookup."""

    def __init__(self, lookup: AlbedoLookup):
        self.lookup = lookup


def test_block_index_tiles_the_texture():
    size = 2 * BLOCK
    blocks = block_index(size).reshape(size, size)
    assert blocks[0, 0] == 0 and blocks[0, BLOCK] == 1 and blocks[BLOCK, 0] == 2 and blocks[-1, -1] == 3
    assert np.bincount(blocks.reshape(-1)).tolist() == [BLOCK * BLOCK] * 4


def test_block_operator_times_the_factors_is_the_scaled_albedo_seen():
    size = 2 * BLOCK
    rng = np.random.default_rng(0)
    texels = torch.from_numpy(rng.integers(0, size * size, 300))
    weights = torch.from_numpy(rng.uniform(0.1, 1.0, 300))
    lookup = AlbedoLookup(torch.arange(300) // 3, texels, weights, (100, size ** 2))
    albedo = torch.from_numpy(rng.uniform(0.2, 0.8, (size, size, 3)))
    factors = rng.uniform(0.5, 2.0, (4, 3))
    scaled = albedo.reshape(-1, 3) * torch.from_numpy(factors[block_index(size)])
    expected = lookup.apply(scaled).numpy()
    np.testing.assert_allclose(np.einsum("pbc,bc->pc", block_operator(Recorded(lookup), albedo), factors), expected)
