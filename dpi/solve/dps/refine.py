"""The last stage of a `dps` sample: the materials refined under the sampled map, with a light touch on it.

Adam on the materials while the map keeps the sample's detail and sun: it gets an order-1
spherical-harmonic log gain (the light's broad balance, which the views determine;
dpi.solve.smooth_gain) and a per-texel polish moving at `lr_texels`, at most about 1 in log over
200 iterations (docs/studies.md, "Refinement", for the variants this won against).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch

from dpi.materials import MaterialRates, MaterialTextures
from dpi.solve.optimize import OptimizeConfig, fit_env_model
from dpi.solve.init import is_glossy
from dpi.solve.problem import InverseProblem
from dpi.solve.smooth_gain import SmoothGain
from dpi.solve.trace import Trace

GAIN_ORDER = 1
"""highest spherical-harmonic band of the gain: a level and a tilt per channel (e.g. the ground against the sky);
band 2 fits the views better but bends the map away from the truth"""


@dataclass
class RefineSettings:
    """Adam settings of the refinement (method_params.dps.refine)."""

    iterations: int = 200
    """Adam iterations on the materials, the gain and the polish"""
    views_per_step: int = 2
    lr_gain: float = 0.03
    """Adam rate of the gain's spherical-harmonic coefficients"""
    lr_texels: float = 0.005
    """Adam rate of the per-texel log polish: at most 1 over 200 iterations, so the sample keeps its detail"""
    glossy_factor: float = 2.0
    """a glossy init (dpi.solve.init.is_glossy) refines this many times longer: the loop does not move the
    roughness a mirror's views hinge on (posterior study's glossy scene, 100 against 50 iterations: views
    +0.5 dB; rough scenes tie at 50, docs/studies.md "the refinement's length")"""

    glossy_lr_texels: float = 0.02
    """the polish's rate on a glossy init: a mirror's views pin its light's detail down, which the prior's grid
    cannot hold (resolution, posterior and calibration studies' metals: views +1.1-2.6 dB, albedo and relighting
    better, env PSNR -0.9..+2.2, the posterior blob's env SSIM 0.85 -> 0.71; at 0.05 its env PSNR lost 4.9 dB;
    docs/studies.md "a freer polish")"""

    def for_init(self, materials: MaterialTextures) -> RefineSettings:
        """These settings for a sample whose init has `materials`: on a glossy one `glossy_factor` times longer,
        and the polish at `glossy_lr_texels`."""
        if not is_glossy(materials):
            return self
        return replace(self, iterations=round(self.iterations * self.glossy_factor), lr_texels=self.glossy_lr_texels)

    def optimize(self, rates: MaterialRates) -> OptimizeConfig:
        """The joint fit's settings: the gain's rate for the map's parameters, `rates` for the textures."""
        return OptimizeConfig(iterations=self.iterations, views_per_step=self.views_per_step, lr_env=self.lr_gain,
                              lr_albedo=rates.lr_albedo, lr_roughness=rates.lr_roughness,
                              lr_metallic=rates.lr_metallic)


def refine(problem: InverseProblem, env: torch.Tensor, materials: MaterialTextures, settings: RefineSettings,
           rates: MaterialRates, seed: int, progress: bool = True) -> tuple[torch.Tensor, MaterialTextures, Trace]:
    """Adam on the materials under `env` with its gain and polish; returns the map, the materials and the trace."""
    trace = Trace()
    model = SmoothGain(env.clamp_min(1e-8).log(), GAIN_ORDER, settings.lr_texels / settings.lr_gain)
    log_env, materials = fit_env_model(problem, model, materials.detached(), settings.optimize(rates), seed, trace,
                                       progress=progress)
    return log_env.exp(), materials, trace
