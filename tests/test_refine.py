"""dps's refinement: the light-only iterations move the map's gain and polish and leave the materials as they are."""

import torch

from dpi.capture import load_capture
from dpi.materials import MaterialRates, MaterialTextures
from dpi.render import RenderConfig
from dpi.solve.dps.refine import RefineConfig, refine
from dpi.solve.problem import InverseProblem, ProblemConfig


def test_light_iterations_fit_the_map_alone(tiny_capture):
    problem = InverseProblem(load_capture(tiny_capture), ProblemConfig(env_height=4, texture_size=8),
                             RenderConfig(spp=2, threads=2))
    materials = MaterialTextures.constant(8)
    env = torch.ones(4, 8, 3)
    settings = RefineConfig(iterations=0, light_iterations=4, views_per_step=1)
    out_env, out_materials, trace = refine(problem, env, materials, settings, MaterialRates(), seed=0, progress=False)
    for name, tensor in materials.items():
        assert torch.equal(dict(out_materials.items())[name], tensor), name
    assert not torch.allclose(out_env, env) and torch.isfinite(out_env).all()
    assert len(trace.steps) == 4
