"""The recorded light transport as a sampler's data term (dpi.solve.transport): no path tracing per step.

A sample records it once, at its first step, under its starting materials (grey albedo, the init's
roughness and metallic) and a few more roughness levels, guided by the init's map; the albedo is a
variable of the transport and the roughness one of its levels, so nothing needs recording again
as they move. Its cost is counted in the step that records it (`seconds_transport`) and in the
trace's info. A resumed sample records it again with the same seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from dpi.solve.decomposition import Decomposition
from dpi.solve.dps.state import DPSRun, DPSState
from dpi.solve.init import starting_materials
from dpi.solve.transport import MAX_TRANSPORT_HEIGHT, LightTransport, TransportSettings, record_transport


@dataclass
class TransportSampling:
    """Settings of a sampler whose data term is the recorded light transport."""

    transport_spp: int = 16
    """paths per pixel of the recording for the light after the first bounce"""
    transport_direct_spp: int = 4
    """camera samples per pixel of the recording's direct light (one shadow ray per texel each)"""
    transport_pixels: int = 2048
    """most foreground pixels of the training views recorded (beyond it an even random subset)"""
    roughness_levels: int = 3
    """roughness levels recorded besides the init's (dpi.solve.transport.roughness_levels)"""
    transport_height: int = MAX_TRANSPORT_HEIGHT
    """most rows of the maps the recording takes (a finer map is sampled at that size)"""

    @property
    def transport(self) -> TransportSettings:
        """The recording's settings."""
        return TransportSettings(self.transport_spp, self.transport_direct_spp, self.transport_pixels,
                                 self.roughness_levels, self.transport_height)

    def transport_for(self, init: Decomposition) -> TransportSettings:
        """The recording's settings for a sample starting from `init` (a sampler may adapt them to it)."""
        return self.transport


def sample_transport(run: DPSRun, state: DPSState) -> tuple[LightTransport, bool]:
    """The sample's transport, recorded at the first call (module notes); and whether this call recorded it."""
    recorded = "transport" not in state.extra
    if recorded:
        state.extra["transport"] = record_transport(run.problem, starting_materials(run.init), run.init.env,
                                                    run.sampler.transport_for(run.init), run.render_seed(0, 97))
    return state.extra["transport"], recorded


def current_level(transport: LightTransport, roughness: torch.Tensor) -> int:
    """The recorded roughness level the sample's roughness texture is (the one closest to it)."""
    return int(torch.argmin(torch.stack([(roughness.detach() - level).abs().mean() for level in transport.roughness])))


def set_level(state: DPSState, transport: LightTransport, level: int) -> None:
    """Make the sample's roughness texture that of a recorded level."""
    with torch.no_grad():
        state.materials.roughness.copy_(transport.roughness[level])
