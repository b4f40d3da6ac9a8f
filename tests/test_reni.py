"""RENI: the decoder's invariants and equivariance (known answers), a short training whose loss falls and whose
checkpoint round-trips and is refused for another family or size, and the `reni` method lowering the views' loss."""

import json

import numpy as np
import pytest
import torch

from dpi.capture import load_capture
from dpi.light.envmap import rotate_azimuth
from dpi.light.tonecurve import family_encoding
from dpi.prior.baselines import CheckpointMismatch
from dpi.prior.data import EnvmapDataset
from dpi.prior.reni import (RENIDecoder, RENINetwork, RENITraining, export_reni, invariants, load_reni, rotate_latent,
                            train_reni)
from dpi.render.renderer import RenderConfig
from dpi.solve.init import InitConfig, path_traced_init
from dpi.solve.optimize import OptimizeConfig
from dpi.solve.problem import InverseProblem, ProblemConfig
from dpi.solve.reni import RENIConfig, reni_sample

SMALL = RENINetwork(latents=4, width=32, layers=2)


def smooth_maps(count: int, height: int) -> torch.Tensor:
    """(count, 3, H, 2H) maps in [-1, 1]: a sky brighter than the ground, a bright patch at a random azimuth."""
    rng = np.random.default_rng(0)
    theta = (np.arange(height) + 0.5) / height * np.pi
    phi = (np.arange(2 * height) + 0.5) / (2 * height) * 2 * np.pi
    maps = []
    for _ in range(count):
        centre = rng.uniform(0, 2 * np.pi)
        patch = np.exp(-((np.cos(phi[None] - centre) - 1) ** 2) * 4 - (theta[:, None] - 1.0) ** 2 * 3)
        base = 0.3 * np.cos(theta)[:, None] + 0.5 * patch - 0.2
        maps.append(np.stack([base, base * 0.9, base * 0.8]))
    return torch.from_numpy(np.array(maps, dtype=np.float32))


def test_turning_or_mirroring_latent_and_direction_together_keeps_the_invariants():
    z, d = torch.randn(2, 4, 3), torch.nn.functional.normalize(torch.randn(2, 7, 3), dim=-1)
    turned = invariants(rotate_latent(z, 37.0), rotate_latent(d, 37.0))
    torch.testing.assert_close(turned, invariants(z, d), atol=1e-5, rtol=1e-5)
    mirror = torch.tensor([-1.0, 1.0, 1.0])
    torch.testing.assert_close(invariants(z * mirror, d * mirror), invariants(z, d), atol=1e-5, rtol=1e-5)
    assert not torch.allclose(invariants(rotate_latent(z, 37.0), d), invariants(z, d), atol=1e-3)


def test_turning_the_latent_turns_the_decoded_map():
    torch.manual_seed(0)
    decoder, z, height = RENIDecoder(SMALL), torch.randn(1, 4, 3), 8
    with torch.no_grad():
        out = decoder.decode(z, height)[0].numpy()
        for columns in (1, 3):
            degrees = 360.0 * columns / (2 * height)
            turned = decoder.decode(rotate_latent(z, degrees), height)[0].numpy()
            np.testing.assert_allclose(turned, rotate_azimuth(out, degrees), atol=1e-4)


def test_training_lowers_the_loss_resumes_and_the_export_round_trips(tmp_path):
    maps = EnvmapDataset(smooth_maps(12, 8), "outdoor", family_encoding("outdoor", "log"))
    cfg = RENITraining(steps=60, batch_size=6, directions=64, lr=1e-3, seed=1)
    out = tmp_path / "reni.pt"
    train_reni(SMALL, RENITraining(**{**vars(cfg), "steps": 30}), maps, out, progress=False)
    assert torch.load(out, weights_only=True)["step"] == 30
    train_reni(SMALL, cfg, maps, out, progress=False)  # resumed: 30 more steps
    log = [line for line in (tmp_path / "reni.log.jsonl").read_text().splitlines()]
    mse = [float(line.split('"mse": ')[1].split(",")[0]) for line in log]
    assert len(mse) == 6 and np.mean(mse[-2:]) < 0.7 * np.mean(mse[:2])
    export_reni(out, tmp_path / "export.pt")
    reni = load_reni(tmp_path / "export.pt", family="outdoor", encoding=maps.encoding, height=8)
    trained = RENIDecoder(SMALL)
    trained.load_state_dict(torch.load(out, weights_only=True)["decoder"])
    z = torch.randn(1, 4, 3)
    with torch.no_grad():
        torch.testing.assert_close(reni.decoder.decode(z, 8), trained.decode(z, 8))
    assert "latent_mean" not in torch.load(tmp_path / "export.pt", weights_only=True)
    with torch.no_grad():  # decoded at its training size, resampled across the sphere to any other
        assert reni.log_radiance(z[0], 16).shape == (16, 32, 3) and reni.log_radiance(z[0], 4).shape == (4, 8, 3)
    with pytest.raises(CheckpointMismatch, match="export.pt: trained for family 'outdoor', not 'indoor'"):
        load_reni(tmp_path / "export.pt", family="indoor")
    with pytest.raises(CheckpointMismatch, match="trained for height 8, not 32"):
        load_reni(tmp_path / "export.pt", height=32)
    torch.save({"model": {}}, tmp_path / "other.pt")
    with pytest.raises(CheckpointMismatch, match="other.pt: not a RENI checkpoint"):
        load_reni(tmp_path / "other.pt")


def test_reni_lowers_the_data_loss_and_seeds_differ(tiny_capture, tmp_path):
    problem = InverseProblem(load_capture(tiny_capture), ProblemConfig(env_height=4, texture_size=8),
                             RenderConfig(spp=4, threads=2))
    maps = EnvmapDataset(smooth_maps(12, 8), "outdoor", family_encoding("outdoor", "log"))
    train_reni(SMALL, RENITraining(steps=40, batch_size=6, directions=64, lr=1e-3), maps, tmp_path / "r.pt",
               progress=False)
    init = path_traced_init(problem, InitConfig(iterations=2, reading="rough"), seed=0, progress=False).kept
    cfg = RENIConfig(optimize=OptimizeConfig(iterations=15, views_per_step=4, lr_env=3e-2), warmup_iterations=20,
                     checkpoint=str(tmp_path / "r.pt"))
    a, b = (reni_sample(problem, init, cfg, seed=seed, progress=False) for seed in (5, 6))
    losses = [s["data"] for s in a.trace.steps]
    assert np.mean(losses[-3:]) < 0.8 * np.mean(losses[:3])
    assert a.env.shape == init.env.shape and torch.isfinite(a.env).all() and (a.env > 0).all()
    assert a.trace.info["prior_weight"] > 0 and a.trace.nan_skips == 0
    assert (a.env - b.env).abs().max() > 1e-4


@pytest.mark.parametrize("method", ["reni", "gan"])
def test_the_sample_stage_draws_a_learned_baseline_with_its_shipped_network(method, tiny_capture, tmp_path):
    from dataclasses import replace

    from dpi.solve.decomposition import Decomposition
    from dpi.stages import capture_stage, init_stage, sample_stage
    from stage_jobs import stage_job

    job = stage_job(tiny_capture, tmp_path / "results", render={"spp": 4},
                    problem={"env_height": 4, "texture_size": 8, "resolution": None}, init={"iterations": 3},
                    method_params={method: {"iterations": 3, "warmup_iterations": 5,
                                            **({"tune_iterations": 2} if method == "gan" else {})}})
    capture_stage(job)
    init_stage(job)
    sample_stage(replace(job, method=method))
    out = job.paths.sample_dir(method, 0)
    trace = json.loads((out / "trace.json").read_text())
    assert trace["info"]["method"] == method and len(trace["steps"]) == (5 if method == "gan" else 3)
    env = Decomposition.load(out).env.numpy()
    assert env.shape[:2] == (4, 8) and np.isfinite(env).all() and (env > 0).all()
