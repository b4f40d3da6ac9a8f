"""A sampled map corrected by a smooth gain: the views' low frequencies on the prior's detail.

A diffuse or rough object filters the light it reflects like a low-pass filter: its views fix the
map's lowest spherical-harmonic bands well (Ramamoorthi and Hanrahan 2001: nine coefficients
carry almost all of a Lambertian object's irradiance) and its finer detail hardly at all. So after
sampling, `dps` can fit a multiplicative gain exp(sum_k c_k Y_k(w)) with real spherical harmonics
up to a low order: where the prior got the broad balance of the light wrong (a ground too dark
under a bright sky), the views correct it, and every texel keeps the sample's detail and its sun.
"""

from __future__ import annotations

import numpy as np
import torch

from dpi.light.envmap import texel_directions
from dpi.solve.optimize import LOG_ENV_RANGE, EnvModel

MAX_ORDER = 2
"""the highest spherical-harmonic band `sh_basis` has"""


def sh_basis(directions: np.ndarray, order: int) -> np.ndarray:
    """Real spherical harmonics of bands 0..order (at most MAX_ORDER) at unit directions (..., 3): (..., (order+1)^2)."""
    if not 0 <= order <= MAX_ORDER:
        raise ValueError(f"spherical-harmonic order must be 0..{MAX_ORDER}, got {order}")
    x, y, z = (directions[..., i] for i in range(3))
    bands = [[0.282095 * np.ones_like(x)],
             [0.488603 * y, 0.488603 * z, 0.488603 * x],
             [1.092548 * x * y, 1.092548 * y * z, 0.315392 * (3 * z * z - 1), 1.092548 * x * z,
              0.546274 * (x * x - y * y)]]
    return np.stack([f for band in bands[: order + 1] for f in band], axis=-1)


class SmoothGain(EnvModel):
    """log-radiance = the given map's + a spherical-harmonic log gain per channel up to band `order`
    (dps uses 1: dpi.solve.dps.refine; coefficients start at 0), and with `polish` > 0 a log residual too, scaled by
    `polish`: under Adam, whose steps do not depend on a gradient's size, it then moves at `polish` times the
    coefficients' rate. The residual is per texel, or with `polish_height` on a coarser grid of that many rows
    bilinearly upsampled: a correction only as fine as the views resolve, the map's finer detail kept."""

    def __init__(self, log_env: torch.Tensor, order: int, polish: float = 0.0, polish_height: int | None = None):
        super().__init__()
        basis = sh_basis(texel_directions(log_env.shape[0]), order)
        self.polish = polish
        self.register_buffer("base", log_env.detach().clone())
        self.register_buffer("basis", torch.as_tensor(basis, dtype=log_env.dtype))
        self.coefficients = torch.nn.Parameter(torch.zeros(basis.shape[-1], 3, dtype=log_env.dtype))
        if polish > 0:
            rows = log_env.shape[0] if polish_height is None else min(polish_height, log_env.shape[0])
            self.texels = torch.nn.Parameter(torch.zeros(rows, 2 * rows, 3, dtype=log_env.dtype))

    def residual(self) -> torch.Tensor:
        """The polish's log residual on the map's grid (bilinear from its own)."""
        if self.texels.shape[:2] == self.base.shape[:2]:
            return self.texels
        up = torch.nn.functional.interpolate(self.texels.permute(2, 0, 1)[None], size=tuple(self.base.shape[:2]),
                                             mode="bilinear", align_corners=False)
        return up[0].permute(1, 2, 0)

    def forward(self) -> torch.Tensor:
        """The base map's log-radiance plus the gain (and the polish), kept inside about [1e-6, 1e6]."""
        log_env = self.base + self.basis @ self.coefficients
        if self.polish > 0:
            log_env = log_env + self.polish * self.residual()
        return log_env.clamp(*LOG_ENV_RANGE)
