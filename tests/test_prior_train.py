"""Prior training on a handful of generated maps: loss falls, runs resume, exported models sample."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import torch

from dpi.io.exr import write_exr
from dpi.io.settings import SettingsError
from dpi.light.tonecurve import LogEncoding, ToneCurve, family_encoding
from dpi.prior.data import EnvmapDataset
from dpi.prior.sample import draw_samples, load_prior, sample_to_files
from dpi.prior.train import TrainConfig, export_model, learning_rate, train
from dpi.prior.unet import SMALL_CONFIGS, CheckpointError, load_checkpoint
from dpi.worlds.outdoor import outdoor_envmap


@pytest.fixture(scope="module")
def maps_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("maps")
    for i in range(4):
        write_exr(folder / f"m{i}.exr", outdoor_envmap(16, np.random.default_rng(i)))
    return folder


def config(steps: int) -> TrainConfig:
    return TrainConfig(model="tiny", steps=steps, batch_size=8, lr=2e-3, sample_every=0, seed=0)


def run(cfg: TrainConfig, tmp_path, maps_dir, data=None) -> dict:
    """Train an outdoor prior on `maps_dir` (or `data`) into tmp_path/model.pt."""
    return train(cfg, "outdoor", maps_dir, tmp_path / "model.pt", data, progress=False)


@pytest.fixture(autouse=True)
def every_step_logged(monkeypatch):
    """Log every step (the tests count losses), checkpoint every 10 and draw sample grids in two reverse steps."""
    monkeypatch.setattr("dpi.prior.train.LOG_EVERY", 1)
    monkeypatch.setattr("dpi.prior.train.CHECKPOINT_EVERY", 10)
    monkeypatch.setattr("dpi.prior.train.SAMPLE_GRID_STEPS", 2)


def logged_losses(tmp_path) -> list[float]:
    return [json.loads(line)["mse"] for line in (tmp_path / "model.log.jsonl").read_text().splitlines()]


def test_loss_falls(tmp_path, maps_dir) -> None:
    torch.set_num_threads(1)
    run(config(30), tmp_path, maps_dir)
    losses = logged_losses(tmp_path)
    assert len(losses) == 30
    assert np.mean(losses[-6:]) < 0.8 * np.mean(losses[:6])


def test_resume_continues_the_step_count(tmp_path, maps_dir) -> None:
    data = EnvmapDataset.from_folder(maps_dir, 16, "outdoor", family_encoding("outdoor"))
    run(config(5), tmp_path, maps_dir, data)
    cfg = config(8)
    cfg.sample_every = 8
    last = run(cfg, tmp_path, maps_dir, data)
    assert last["step"] == 8 and len(logged_losses(tmp_path)) == 8
    assert torch.load(tmp_path / "model.pt", weights_only=True)["step"] == 8
    assert (tmp_path / "model_samples" / "step_000008.png").is_file()


def test_exported_model_samples(tmp_path, maps_dir) -> None:
    run(config(2), tmp_path, maps_dir)
    export_model(tmp_path / "model.pt", tmp_path / "shipped.pt")
    shipped = torch.load(tmp_path / "shipped.pt", weights_only=True)
    assert "optimizer" not in shipped and shipped["model"]["out.2.weight"].dtype == torch.float16
    prior = load_prior(tmp_path / "shipped.pt")
    assert prior.family == "outdoor" and prior.height == 16 and prior.encoding == LogEncoding()
    assert prior.median_target == 1.0
    x = draw_samples(prior, 1, steps=3)
    assert x.shape == (1, 3, 16, 32) and torch.isfinite(x).all() and x.abs().max() <= 1
    paths = sample_to_files(tmp_path / "shipped.pt", tmp_path / "samples", count=2, steps=2)
    assert len(paths) == 2 and (tmp_path / "samples" / "samples.png").is_file()


def test_paper_encoding_is_recorded_and_loads(tmp_path, maps_dir) -> None:
    cfg = config(1)
    cfg.encoding = "paper"
    run(cfg, tmp_path, maps_dir)
    export_model(tmp_path / "model.pt", tmp_path / "shipped.pt")
    prior = load_prior(tmp_path / "shipped.pt")
    assert prior.encoding == ToneCurve(0.5, 2.4) and prior.median_target == 0.3


def test_cosine_schedule_warms_up_then_decays_to_zero() -> None:
    cfg = TrainConfig(steps=100, lr=1e-3, warmup_steps=10, lr_schedule="cosine")
    assert learning_rate(cfg, 0) == pytest.approx(1e-4 * 0.5 * (1 + np.cos(0.0)))
    assert learning_rate(cfg, 50) == pytest.approx(0.5e-3)
    assert learning_rate(cfg, 100) == pytest.approx(0.0, abs=1e-12)
    cfg.lr_schedule = "constant"
    assert learning_rate(cfg, 50) == learning_rate(cfg, 99) == 1e-3
    with pytest.raises(SettingsError, match="lr_schedule: unknown schedule 'linear'"):
        TrainConfig(lr_schedule="linear")
    with pytest.raises(SettingsError, match="model: unknown network 'huge'"):
        TrainConfig(model="huge")


def test_fine_tune_starts_from_the_given_prior(tmp_path, maps_dir) -> None:
    """A run with `init` starts from that prior's weights: at learning rate 0 its EMA stays them exactly."""
    run(config(3), tmp_path, maps_dir)
    export_model(tmp_path / "model.pt", tmp_path / "shipped.pt")
    cfg = config(2)
    cfg.init, cfg.lr = str(tmp_path / "shipped.pt"), 0.0
    train(cfg, "outdoor", maps_dir, tmp_path / "tuned.pt", progress=False)
    before = load_checkpoint(tmp_path / "shipped.pt").float().state_dict()
    after = load_checkpoint(tmp_path / "tuned.pt").state_dict()
    assert all(torch.equal(before[k], after[k]) for k in before)
    cfg.model = "small_32x64"
    with pytest.raises(CheckpointError, match="shipped.pt"):
        train(cfg, "outdoor", maps_dir, tmp_path / "other.pt", progress=False)


def test_a_prior_starts_a_run_at_twice_its_map_size(tmp_path, maps_dir, monkeypatch) -> None:
    """The network is convolutional: a 16-row prior's weights start a 32-row run of the same network."""
    run(config(2), tmp_path, maps_dir)
    export_model(tmp_path / "model.pt", tmp_path / "small.pt")
    monkeypatch.setitem(SMALL_CONFIGS, "tiny_32", replace(SMALL_CONFIGS["tiny"], image_size=32))
    cfg = config(1)
    cfg.init, cfg.lr, cfg.model = str(tmp_path / "small.pt"), 0.0, "tiny_32"
    train(cfg, "outdoor", maps_dir, tmp_path / "large.pt", progress=False)
    before = load_checkpoint(tmp_path / "small.pt").float().state_dict()
    large = load_prior(tmp_path / "large.pt")
    assert large.height == 32
    assert all(torch.equal(before[k], v) for k, v in large.model.state_dict().items())
