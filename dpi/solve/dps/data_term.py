"""The recorded light transport as a sampler's data term (dpi.solve.transport): no path tracing per step.

A sample records it once, at its first step, under its starting materials (grey albedo, the init's
roughness and metallic) and a few more roughness levels, guided by the init's map; the albedo is a
variable of the transport and the roughness one of its levels, so nothing needs recording again
as they move. Its cost is counted in the step that records it (`seconds_transport`) and in the
trace's info. A resumed sample records it again with the same seed.
"""

from __future__ import annotations

import torch

from dpi.solve.dps.state import DPSRun, DPSState
from dpi.solve.init import is_glossy, starting_materials
from dpi.solve.transport import GLOSSY_RECORDING, ROUGH_RECORDING, LightTransport, Recording, record_transport


def recording_for(run: DPSRun) -> Recording:
    """A glossy init's recording has roughness levels and finer maps (dpi.solve.transport.GLOSSY_RECORDING), a rough
    one's neither: the same glossy test as DPSConfig.for_init."""
    return GLOSSY_RECORDING if is_glossy(run.init.materials) else ROUGH_RECORDING


def sample_transport(run: DPSRun, state: DPSState) -> tuple[LightTransport, bool]:
    """The sample's transport, recorded at the first call (module notes); and whether this call recorded it."""
    recorded = "transport" not in state.extra
    if recorded:
        state.extra["transport"] = record_transport(run.problem, starting_materials(run.init), run.init.env,
                                                    run.sampler.transport, run.render_seed(0, 97), recording_for(run))
    return state.extra["transport"], recorded


def current_level(transport: LightTransport, roughness: torch.Tensor) -> int:
    """The recorded roughness level the sample's roughness texture is (the one closest to it)."""
    return int(torch.argmin(torch.stack([(roughness.detach() - level).abs().mean() for level in transport.roughness])))


def set_level(state: DPSState, transport: LightTransport, level: int) -> None:
    """Make the sample's roughness texture that of a recorded level."""
    with torch.no_grad():
        state.materials.roughness.copy_(transport.roughness[level])
