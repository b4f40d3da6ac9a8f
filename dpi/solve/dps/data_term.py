"""The recorded light transport as a sampler's data term (dpi.solve.transport): no path tracing per step.

A sample records it once, at its first step, under its starting materials (DPSConfig.start_materials),
guided by the init's map; the albedo is a variable of the transport, so nothing needs
recording again as it moves, and the roughness stays the init's until the refinement path-traces it (a choice
among recorded roughness levels, tried before, kept the init's on every study scene). Its cost is counted in the
step that records it (`seconds_transport`) and in the trace's info. A resumed sample records it again with the
same seed.
"""

from __future__ import annotations

from dpi.solve.decomposition import Decomposition
from dpi.solve.dps.state import DPSRun, DPSState
from dpi.solve.init import is_glossy
from dpi.solve.materials import MaterialTextures
from dpi.solve.problem import InverseProblem
from dpi.solve.transport import (MAX_TRANSPORT_HEIGHT, ROUGH_TRANSPORT_HEIGHT, LightTransport, TransportConfig,
                                 record_transport)


def sample_transport(run: DPSRun, state: DPSState) -> tuple[LightTransport, bool]:
    """The sample's transport, recorded at the first call (module notes); and whether this call recorded it. A
    glossy init's (the same test as DPSConfig.for_init) takes larger maps, whose detail its views resolve, and draws
    the direct light only for the bright texels, its narrow lobe sampled by the BSDF; a rough one's takes the low
    frequencies its views see, every texel drawn."""
    recorded = "transport" not in state.extra
    if recorded:
        state.extra["transport"] = start_transport(run.problem, run.init, run.cfg.start_materials(run.init),
                                                   run.sampler.transport, run.render_seed(0, 97))
    return state.extra["transport"], recorded


def start_transport(problem: InverseProblem, init: Decomposition, start: MaterialTextures, settings: TransportConfig,
                    seed: int) -> LightTransport:
    """The transport a sample from `init` records under its starting materials `start` (sample_transport), recorded
    with `seed`."""
    glossy = is_glossy(init.materials)
    return record_transport(problem, start, init.env, settings, seed,
                            MAX_TRANSPORT_HEIGHT if glossy else ROUGH_TRANSPORT_HEIGHT, every_texel=not glossy)
