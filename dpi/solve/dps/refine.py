"""The last stage of a `dps` sample: the materials refined under the sampled map, with a light touch on it.

Adam on the materials while the map keeps the sample's detail and sun: it gets an order-1
spherical-harmonic log gain (the light's broad balance, which the views determine;
dpi.solve.smooth_gain) and a polish moving at `lr_texels` on the grid the sample's transport saw (a rough object's
views fix the light that coarsely; a glossy one's polish is per texel, dpi.solve.dps.start). It runs as long as a
plain fit does (dpi.solve.classic): a sample explains its photos as well as a fit of them (docs/studies.md,
"Refinement").
"""

from __future__ import annotations

import torch

from dpi.io.settings import Count, Rate, Steps, settings
from dpi.solve.materials import MaterialRates, MaterialTextures
from dpi.solve.optimize import OptimizeConfig, fit_env_model
from dpi.solve.problem import InverseProblem
from dpi.solve.smooth_gain import SmoothGain
from dpi.solve.trace import Trace

GAIN_ORDER = 1
"""highest spherical-harmonic band of the gain: a level and a tilt per channel (e.g. the ground against the sky);
band 2 fits the views better but bends the map away from the truth"""


@settings
class RefineConfig:
    """Adam settings of the refinement (method_params.dps.refine)."""

    iterations: Steps = 150
    """Adam iterations on the materials, the gain and the polish: a plain fit's (the paper preset: 200)"""
    views_per_step: Count = 1
    """training views rendered per iteration: the materials converge with Adam's steps, not the views a step sees"""
    lr_gain: Rate = 0.03
    """Adam rate of the gain's spherical-harmonic coefficients"""
    lr_texels: Rate = 0.03
    """Adam rate of the log polish on the transport's grid (the gain's): the views correct the light as finely as
    they resolve it, the finer detail stays the sample's"""
    def optimize(self, rates: MaterialRates) -> OptimizeConfig:
        """The joint fit's settings: the gain's rate for the map's parameters, `rates` for the textures."""
        return OptimizeConfig(iterations=self.iterations, views_per_step=self.views_per_step, lr_env=self.lr_gain,
                              lr_albedo=rates.lr_albedo)


def refine(problem: InverseProblem, env: torch.Tensor, materials: MaterialTextures, settings: RefineConfig,
           rates: MaterialRates, seed: int, polish_height: int | None, progress: bool = True
           ) -> tuple[torch.Tensor, MaterialTextures, Trace]:
    """Adam on the materials under `env` with its gain and its polish on a grid of `polish_height` rows (None: per
    texel); returns the map, the materials and the trace."""
    trace = Trace()
    model = SmoothGain(env.clamp_min(1e-8).log(), GAIN_ORDER, settings.lr_texels / settings.lr_gain, polish_height)
    log_env, materials = fit_env_model(problem, model, materials.detached(), settings.optimize(rates), seed, trace,
                                       progress=progress)
    return log_env.exp(), materials, trace
