"""dpi: Diffusion Posterior Illumination, ambiguity-aware inverse rendering."""

import os

# torch's OpenMP threads spin while they wait by default; next to other jobs on a shared CPU that
# made the prior's network ~30x slower (benchmarks/timing/dps_step.py). Set before torch loads OpenMP.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
