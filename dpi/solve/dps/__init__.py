"""Diffusion posterior sampling with an optimisable measurement operator (the paper's method, `dps`).

Reverse diffusion over the prior's image space x (encoded env maps in [-1, 1]), guided by the
views, with the materials fitted jointly; after the last step the materials are refined under the
clean map by path tracing (`refine`). How one reverse step uses the data is the `sampler` setting,
each in its own module with its own settings: `proximal` (x0-space data steps on the views' recorded light
transport, `data_term`) and `paper` (the reference's gradient guidance through the path tracer). The modules:

- config: DPSConfig (method_params.dps) and the samplers by name
- state: the fixed run and the loop state a step advances
- start: the materials a sample starts from
- loop: start_run, posterior_steps (the loop as a generator), dps_phases (the sample phase by phase) and dps_sample
- data_term: the recorded light transport as a sampler's data term
- proximal, paper: one sampler each
- map_solve: the map's Gauss-Newton solve on the transport (proximal's per-step solve)
- sun_choice: the parametric sun's settings and when a sample gets one
- refine: the refinement
"""

from dpi.solve.dps.config import SAMPLERS, DPSConfig
from dpi.solve.dps.loop import DPSResult, dps_phases, dps_sample, posterior_steps, start_run

__all__ = ["SAMPLERS", "DPSConfig", "DPSResult", "dps_phases", "dps_sample", "posterior_steps", "start_run"]
