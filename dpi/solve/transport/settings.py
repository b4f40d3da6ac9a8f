"""How a light transport is recorded (its settings) and the map size it takes."""

from __future__ import annotations

from typing import Annotated

from pydantic import Field

from dpi.io.settings import Count, settings

MAX_TRANSPORT_HEIGHT = 32
"""the largest map (rows) a transport takes by default (the shipped priors' size): its normal equations take
(2 H^2)^2 x 3 floats (100 MB at 32 rows, 1.6 GB at 64) and its direct light one shadow ray per texel per camera
sample, so its recording and products grow with the texels (4x from 16 to 32 rows)"""


HALVES = 2
"""independent recordings of every transport (module notes)"""


Halves = Annotated[int, Field(ge=HALVES, multiple_of=HALVES)]
"""samples split evenly between the transport's two halves"""


@settings
class TransportConfig:
    """How the light transport is recorded (method_params.dps.<sampler>.transport)."""

    spp: Halves = 16
    """paths per pixel for the light after the first bounce (split between the two halves); the direct light takes
    a quarter of that in camera samples, each with one shadow ray per texel (`direct_spp`)"""
    pixels: Count = 8192
    """most foreground pixels of the training views recorded: beyond it, an even random subset standing for the rest
    (every pixel of a small capture; the albedo's texels and the light's balance are seen through these, and the
    recording's time and memory grow with them: 200 MB at 16 rows)"""

    @property
    def direct_spp(self) -> int:
        """Camera samples per pixel of the direct light: a quarter of `spp`, split evenly between the halves."""
        return max(HALVES, self.spp // (4 * HALVES) * HALVES)


ROUGH_TRANSPORT_HEIGHT = 16
"""the largest map (rows) a rough object's transport takes: its views fix the light's low frequencies only, and the
recording's cost grows with the texels (a glossy object's views resolve detail up to MAX_TRANSPORT_HEIGHT)"""


def transport_height(env_height: int, max_height: int = MAX_TRANSPORT_HEIGHT) -> int:
    """The rows of the maps a transport takes: the problem's map, at most `max_height` (a finer map is sampled at
    that size and upsampled; its finer detail is the path-traced refinement's)."""
    return min(env_height, max_height)
