"""The true textures carried onto another atlas of the same surface (dpi.evaluation.truth): a known answer, and a
scanner-like synthetic capture through the uv stage."""

from __future__ import annotations

import numpy as np

from dpi.evaluation.truth import surface_lookup
from dpi.preprocess.uv import bake, uv_atlas
from dpi.render.texels import chart_texels
from dpi.synth.capture import scanned
from dpi.synth.shapes import blob


def colour_field(points: np.ndarray) -> np.ndarray:
    """A smooth RGB function of position in [0, 1]."""
    x, y, z = points.T
    return 0.5 + 0.5 * np.stack([np.sin(2 * x), np.sin(3 * y + 1), np.sin(2 * z - x)], -1)


def test_a_texture_of_position_carried_to_a_scans_atlas_is_the_same_function_there():
    truth = blob(resolution=32, seed=4)
    texture = bake(truth, colour_field, 64)
    surface = {"positions": truth.vertices, "faces": truth.faces, "uvs": truth.uvs}
    scan, _ = uv_atlas(*scanned("blob", 4, 20_000), 64)
    carried = bake(scan, lambda points: surface_lookup(surface, [texture], points), 64)
    direct = bake(scan, colour_field, 64)
    inside = chart_texels(scan.uvs, scan.faces, 64)
    error = np.abs(carried - direct)[inside]
    assert error.mean() < 0.02 and np.quantile(error, 0.99) < 0.1
    shuffled = bake(scan, lambda points: colour_field(points[::-1]), 64)  # the same values at the wrong points
    assert np.abs(shuffled - direct)[inside].mean() > 10 * error.mean()


def test_a_scanned_capture_is_scored_on_its_own_atlas(tmp_path, mi):
    from conftest import TINY_SYNTH

    from dpi.capture import load_capture
    from dpi.evaluation.train_fit import training_fit
    from dpi.evaluation.truth import true_decomposition
    from dpi.io.layout import geometry_files
    from dpi.io.atomic import write_json
    from dpi.preprocess.derive import derive_uv
    from dpi.render.renderer import RenderConfig
    from dpi.solve.decomposition import Decomposition
    from dpi.solve.materials import MaterialTextures
    from dpi.solve.problem import InverseProblem, ProblemConfig
    from dpi.synth.capture import SynthConfig, make_synthetic_capture

    root = tmp_path / "scan"
    make_synthetic_capture(root, SynthConfig(**{**TINY_SYNTH, "scan_faces": 5000}), threads=2, progress=False)
    capture = load_capture(root)
    assert not capture.mesh_has_uv and (root / "gt" / "mesh.ply").is_file()
    write_json(tmp_path / "capture.json", capture.to_json())
    summary = derive_uv(tmp_path / "capture.json", tmp_path / "geometry", 16)
    assert summary["given_faces"] >= 5000
    problem = InverseProblem(capture.with_derived(mesh=geometry_files(tmp_path / "geometry")["mesh_uv"]),
                             ProblemConfig(env_height=8, texture_size=16), RenderConfig(spp=4, threads=2))
    truth = true_decomposition(problem)
    assert truth is not None
    grey = Decomposition(truth.env, MaterialTextures.constant(16, 0.5, 0.5, 0.0))
    assert training_fit(problem, truth, spp=4, seed=0) < 0.3 * training_fit(problem, grey, spp=4, seed=0)
