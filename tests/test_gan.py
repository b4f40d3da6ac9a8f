"""The GAN baseline: seamless maps of the prior's size, a short training that moves the generated maps towards the
data and whose checkpoint round-trips and is refused for another family or size, and the `gan` method (latent stage
then pivotal tuning) lowering the views' loss."""

import numpy as np
import pytest
import torch

from dpi.capture import load_capture
from dpi.light.tonecurve import family_encoding
from dpi.prior.baselines import CheckpointMismatch
from dpi.prior.data import EnvmapDataset
from dpi.prior.gan import GANNetwork, GANTraining, Generator, export_gan, load_gan, train_gan
from dpi.render.renderer import RenderConfig
from dpi.solve.gan import GANConfig, gan_sample
from dpi.solve.init import InitConfig, path_traced_init
from dpi.solve.optimize import OptimizeConfig
from dpi.solve.problem import InverseProblem, ProblemConfig
from test_reni import smooth_maps

SMALL = GANNetwork(latent=8, channels=8, height=8)


def test_generated_maps_have_the_prior_size_and_no_seam():
    torch.manual_seed(0)
    x = Generator(SMALL)(torch.randn(4, 8)).detach()
    assert x.shape == (4, 3, 8, 16) and x.abs().max() <= 1
    seam = (x[..., 0] - x[..., -1]).abs().mean()  # the first and last columns are neighbours on the sphere
    inside = (x[..., 1:] - x[..., :-1]).abs().mean()
    assert seam < 2 * inside
    with pytest.raises(ValueError, match="4 times a power of two"):
        Generator(GANNetwork(height=12))


def test_training_moves_the_maps_towards_the_data_and_the_export_round_trips(tmp_path):
    maps = EnvmapDataset(smooth_maps(16, 8), "outdoor", family_encoding("outdoor", "log"))
    target = maps.images.mean(dim=(0, 2, 3))
    z = torch.randn(64, 8, generator=torch.Generator().manual_seed(3))
    out = tmp_path / "gan.pt"
    train_gan(SMALL, GANTraining(steps=1, batch_size=8, seed=1), maps, out, progress=False)
    before = load_gan(out).generator(z).mean(dim=(0, 2, 3))
    train_gan(SMALL, GANTraining(steps=150, batch_size=8, seed=1, ema_decay=0.9), maps, out, progress=False)
    after = load_gan(out).generator(z).mean(dim=(0, 2, 3))
    assert (after - target).abs().mean() < 0.5 * (before - target).abs().mean()
    assert torch.load(out, weights_only=True)["step"] == 150
    export_gan(out, tmp_path / "export.pt")
    gan = load_gan(tmp_path / "export.pt", family="outdoor", encoding=maps.encoding, height=8)
    torch.testing.assert_close(gan.generator(z), load_gan(out).generator(z))
    assert "discriminator" not in torch.load(tmp_path / "export.pt", weights_only=True)
    with pytest.raises(CheckpointMismatch, match="export.pt: trained for family 'outdoor', not 'indoor'"):
        load_gan(tmp_path / "export.pt", family="indoor")
    with pytest.raises(CheckpointMismatch, match="trained for height 8, not 32"):
        load_gan(tmp_path / "export.pt", height=32)
    torch.save({"format": "dpi-reni-1"}, tmp_path / "other.pt")
    with pytest.raises(CheckpointMismatch, match="other.pt: not a GAN checkpoint"):
        load_gan(tmp_path / "other.pt")


def test_gan_lowers_the_data_loss_in_both_stages_and_seeds_differ(tiny_capture, tmp_path):
    problem = InverseProblem(load_capture(tiny_capture), ProblemConfig(env_height=4, texture_size=8),
                             RenderConfig(spp=4, threads=2))
    maps = EnvmapDataset(smooth_maps(16, 8), "outdoor", family_encoding("outdoor", "log"))
    train_gan(SMALL, GANTraining(steps=20, batch_size=8), maps, tmp_path / "g.pt", progress=False)
    init = path_traced_init(problem, InitConfig(iterations=2, reading="rough"), seed=0, progress=False).kept
    cfg = GANConfig(optimize=OptimizeConfig(iterations=12, views_per_step=4, lr_env=3e-2), tune_iterations=8,
                    warmup_iterations=20, checkpoint=str(tmp_path / "g.pt"))
    a, b = (gan_sample(problem, init, cfg, seed=seed, progress=False) for seed in (5, 6))
    losses = [s["data"] for s in a.trace.steps]
    assert len(losses) == 20 and np.mean(losses[-3:]) < 0.8 * np.mean(losses[:3])
    assert a.env.shape == init.env.shape and torch.isfinite(a.env).all() and (a.env > 0).all()
    assert a.trace.info["tune_weight"] > 0 and a.trace.nan_skips == 0
    assert (a.env - b.env).abs().max() > 1e-4
