"""The recorded light transport as a sampler's data term (dpi.solve.transport): no path tracing per step.

A sample records it once, at its first step, under its starting materials (DPSConfig.start_materials),
guided by the init's map; the albedo is a variable of the transport, so nothing needs
recording again as it moves, and the roughness stays the start's until the refinement path-traces it. Its cost is
counted in the step that records it (`seconds_transport`) and in the trace's info. With `proximal.lobe_choice` a
rough init's sample records it before its first step instead, at several lobe widths, and keeps the one its views
favour (dpi.solve.dps.lobe_choice; its seconds in the trace's info only). A resumed sample records it again with
the same seed.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from dpi.solve.decomposition import Decomposition
from dpi.solve.dps.lobe_choice import LOBE_FACTORS, favoured_level
from dpi.solve.dps.state import DPSRun, DPSState
from dpi.solve.init import is_glossy
from dpi.solve.materials import MaterialTextures
from dpi.solve.problem import InverseProblem
from dpi.solve.transport import (MAX_TRANSPORT_HEIGHT, ROUGH_TRANSPORT_HEIGHT, LightTransport, TransportConfig,
                                 record_transport)

LOBE_TRANSPORT = "lobe_transport"
"""state.extra's key of the transport `choose_lobe_` recorded, until the first step takes it"""


def sample_transport(run: DPSRun, state: DPSState) -> tuple[LightTransport, bool]:
    """The sample's transport, recorded at the first call (module notes); and whether this call recorded it. A
    glossy init's (the same test as DPSConfig.for_init) takes larger maps, whose detail its views resolve, and draws
    the direct light only for the bright texels, its narrow lobe sampled by the BSDF; a rough one's takes the low
    frequencies its views see, every texel drawn."""
    recorded = "transport" not in state.extra
    if recorded:
        state.extra["transport"] = state.extra.pop(LOBE_TRANSPORT, None) or start_transport(
            run.problem, run.init, run.cfg.start_materials(run.init), run.sampler.transport, run.render_seed(0, 97))
    return state.extra["transport"], recorded


def choose_lobe_(run: DPSRun, state: DPSState) -> None:
    """With `lobe_choice`, on a rough init: the sample's transport recorded at LOBE_FACTORS more lobe widths, and
    the level its views favour under the start's albedo kept as its transport and its roughness (module notes). At
    the sample's start, before a resumed sample's state is restored over it."""
    if not getattr(run.sampler, "lobe_choice", False) or is_glossy(run.init.materials):
        return
    start = run.cfg.start_materials(run.init)
    transport = start_transport(run.problem, run.init, start, run.sampler.transport, run.render_seed(0, 97),
                                LOBE_FACTORS)
    level, shares = favoured_level(transport, start.albedo)
    state.extra[LOBE_TRANSPORT] = transport.at_level(level)
    state.extra["lobe"] = {"factor": round((1.0, *LOBE_FACTORS)[level], 4),
                           "unexplained": [round(s, 5) for s in shares]}
    with torch.no_grad():
        state.materials.roughness.copy_(transport.roughness[level])


def start_transport(problem: InverseProblem, init: Decomposition, start: MaterialTextures, settings: TransportConfig,
                    seed: int, levels: Sequence[float] = ()) -> LightTransport:
    """The transport a sample from `init` records under its starting materials `start` (sample_transport), recorded
    with `seed`, and at `levels` more lobe widths (transport.lobe_levels)."""
    glossy = is_glossy(init.materials)
    return record_transport(problem, start, init.env, settings, seed,
                            MAX_TRANSPORT_HEIGHT if glossy else ROUGH_TRANSPORT_HEIGHT, levels, not glossy)
