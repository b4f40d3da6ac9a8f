"""The recorded light transport as a sampler's data term (dpi.solve.transport): no path tracing per step.

A sample records it once, at its first step, under its starting materials (dpi.solve.dps.start), guided by the
init's map; the albedo is a variable of the transport, so nothing needs recording again as it moves, and the
roughness stays the start's until the refinement path-traces it. Its cost is counted in the step that records it
(`seconds_transport`) and in the trace's info. A resumed sample records it again with the same seed.
"""

from __future__ import annotations

from dpi.solve.dps.start import sample_start_materials, start_transport
from dpi.solve.dps.state import DPSRun, DPSState
from dpi.solve.transport import LightTransport


def sample_transport(run: DPSRun, state: DPSState) -> tuple[LightTransport, bool]:
    """The sample's transport, recorded at the first call (module notes); and whether this call recorded it."""
    recorded = "transport" not in state.extra
    if recorded:
        state.extra["transport"] = start_transport(run.problem, run.init, sample_start_materials(run.init),
                                                   run.sampler.transport, run.render_seed(0, 97))
    return state.extra["transport"], recorded
