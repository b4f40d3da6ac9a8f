"""The guided-diffusion UNet re-implementation: key/shape layout, non-square inputs, strict loading."""

from __future__ import annotations

import pytest
import torch

from dpi.prior.unet import (PAPER_CONFIG, SMALL_CONFIGS, CheckpointError, UNetConfig, UNetModel,
                            attention_ds_from_resolutions, load_checkpoint)


def resblock_keys(prefix: str, cin: int, cout: int, emb: int, scale_shift: bool) -> dict[str, tuple]:
    """Parameters guided-diffusion's ResBlock(cin -> cout) holds (up/down variants add none)."""
    keys = {
        "in_layers.0.weight": (cin,), "in_layers.0.bias": (cin,),
        "in_layers.2.weight": (cout, cin, 3, 3), "in_layers.2.bias": (cout,),
        "emb_layers.1.weight": ((2 if scale_shift else 1) * cout, emb), "emb_layers.1.bias": ((2 if scale_shift else 1) * cout,),
        "out_layers.0.weight": (cout,), "out_layers.0.bias": (cout,),
        "out_layers.3.weight": (cout, cout, 3, 3), "out_layers.3.bias": (cout,),
    }
    if cin != cout:
        keys |= {"skip_connection.weight": (cout, cin, 1, 1), "skip_connection.bias": (cout,)}
    return {f"{prefix}.{k}": v for k, v in keys.items()}


def attention_keys(prefix: str, c: int) -> dict[str, tuple]:
    """Parameters of guided-diffusion's AttentionBlock(c)."""
    keys = {"norm.weight": (c,), "norm.bias": (c,), "qkv.weight": (3 * c, c, 1), "qkv.bias": (3 * c,),
            "proj_out.weight": (c, c, 1), "proj_out.bias": (c,)}
    return {f"{prefix}.{k}": v for k, v in keys.items()}


def expected_layout(cfg: UNetConfig) -> dict[str, tuple]:
    """Key -> shape that guided-diffusion's UNetModel builds for `cfg` (resblock_updown, scale-shift)."""
    m, emb, ss = cfg.num_channels, 4 * cfg.num_channels, True
    keys = {"time_embed.0.weight": (emb, m), "time_embed.0.bias": (emb,),
            "time_embed.2.weight": (emb, emb), "time_embed.2.bias": (emb,),
            "input_blocks.0.0.weight": (m, 3, 3, 3), "input_blocks.0.0.bias": (m,)}
    ch, ds, n, skips = m, 1, 1, [m]
    for level, mult in enumerate(cfg.channel_mult):
        for _ in range(cfg.num_res_blocks):
            keys |= resblock_keys(f"input_blocks.{n}.0", ch, mult * m, emb, ss)
            ch = mult * m
            if ds in cfg.attention_ds:
                keys |= attention_keys(f"input_blocks.{n}.1", ch)
            skips.append(ch)
            n += 1
        if level < len(cfg.channel_mult) - 1:
            keys |= resblock_keys(f"input_blocks.{n}.0", ch, ch, emb, ss)
            skips.append(ch)
            n, ds = n + 1, ds * 2
    keys |= resblock_keys("middle_block.0", ch, ch, emb, ss) | attention_keys("middle_block.1", ch)
    keys |= resblock_keys("middle_block.2", ch, ch, emb, ss)
    n = 0
    for level, mult in reversed(list(enumerate(cfg.channel_mult))):
        for i in range(cfg.num_res_blocks + 1):
            keys |= resblock_keys(f"output_blocks.{n}.0", ch + skips.pop(), mult * m, emb, ss)
            ch, j = mult * m, 1
            if ds in cfg.attention_ds:
                keys |= attention_keys(f"output_blocks.{n}.1", ch)
                j = 2
            if level and i == cfg.num_res_blocks:
                keys |= resblock_keys(f"output_blocks.{n}.{j}", ch, ch, emb, ss)
                ds //= 2
            n += 1
    keys |= {"out.0.weight": (ch,), "out.0.bias": (ch,), "out.2.weight": (cfg.out_channels, ch, 3, 3),
             "out.2.bias": (cfg.out_channels,)}
    return keys


@pytest.fixture(scope="module")
def paper_model() -> UNetModel:
    with torch.device("meta"):
        return UNetModel(PAPER_CONFIG)


def test_paper_config_flags() -> None:
    assert attention_ds_from_resolutions(256, "32,16,8") == (8, 16, 32)
    assert PAPER_CONFIG.out_channels == 6


def test_a_checkpoint_config_may_carry_the_fixed_guided_diffusion_flags() -> None:
    """A config listing guided-diffusion's flags at the values dpi's UNet implements (and its training-only dropout,
    the authors' 0.1) reads back as the same config; another value is refused, naming the flag."""
    from dpi.prior.unet import GUIDED_DIFFUSION_FIXED, CheckpointError

    stored = {**PAPER_CONFIG.to_dict(), **GUIDED_DIFFUSION_FIXED, "dropout": 0.1}
    assert UNetConfig.from_dict(stored) == PAPER_CONFIG
    with pytest.raises(CheckpointError, match="resblock_updown must be True"):
        UNetConfig.from_dict({**stored, "resblock_updown": False})
    with pytest.raises(CheckpointError, match="learn_sigma must be True"):
        UNetConfig.from_dict({**stored, "learn_sigma": False})


def test_paper_layout_matches_guided_diffusion_rules(paper_model: UNetModel) -> None:
    got = {k: tuple(v.shape) for k, v in paper_model.state_dict().items()}
    want = expected_layout(PAPER_CONFIG)
    assert sorted(set(want) - set(got)) == []
    assert sorted(set(got) - set(want)) == []
    assert {k: got[k] for k in want} == want


def test_paper_layout_spot_checks(paper_model: UNetModel) -> None:
    sd = paper_model.state_dict()
    assert len(paper_model.input_blocks) == 1 + 6 * 3 + 5
    assert len(paper_model.output_blocks) == 6 * 4
    assert tuple(sd["input_blocks.0.0.weight"].shape) == (256, 3, 3, 3)
    assert tuple(sd["out.2.weight"].shape) == (6, 256, 3, 3)
    assert tuple(sd["time_embed.0.weight"].shape) == (1024, 256)
    assert tuple(sd["input_blocks.1.0.emb_layers.1.weight"].shape) == (512, 1024)  # scale and shift
    assert tuple(sd["input_blocks.9.0.skip_connection.weight"].shape) == (512, 256, 1, 1)
    assert tuple(sd["input_blocks.13.1.qkv.weight"].shape) == (1536, 512, 1)  # first attention: ds 8
    assert "input_blocks.12.1.qkv.weight" not in sd and "input_blocks.4.0.op.weight" not in sd
    assert tuple(sd["middle_block.1.qkv.weight"].shape) == (3072, 1024, 1)
    assert tuple(sd["output_blocks.0.0.in_layers.0.weight"].shape) == (2048,)
    assert tuple(sd["output_blocks.3.2.in_layers.2.weight"].shape) == (1024, 1024, 3, 3)  # up ResBlock
    assert paper_model.middle_block[1].num_heads == 1024 // 64


@pytest.mark.parametrize("name", sorted(SMALL_CONFIGS))
def test_small_configs_follow_the_same_rules(name: str) -> None:
    model = UNetModel(SMALL_CONFIGS[name])
    assert {k: tuple(v.shape) for k, v in model.state_dict().items()} == expected_layout(SMALL_CONFIGS[name])


def test_non_square_forward() -> None:
    model = UNetModel(SMALL_CONFIGS["tiny"])
    torch.nn.init.normal_(model.out[2].weight)  # zero-initialised output would hide shape bugs
    y = model(torch.randn(2, 3, 16, 32), torch.tensor([3, 900]))
    assert y.shape == (2, 6, 16, 32) and torch.isfinite(y).all()


def test_rejects_indivisible_size() -> None:
    with pytest.raises(ValueError, match="divisible"):
        UNetModel(SMALL_CONFIGS["tiny"])(torch.randn(1, 3, 15, 30), torch.tensor([1]))


def test_raw_state_dict_round_trip(tmp_path) -> None:
    cfg = SMALL_CONFIGS["tiny"]
    model = UNetModel(cfg)
    torch.save(model.state_dict(), tmp_path / "raw.pt")
    loaded = load_checkpoint(tmp_path / "raw.pt", cfg)
    x, t = torch.randn(1, 3, 16, 32), torch.tensor([5])
    assert torch.equal(loaded(x, t), model.eval()(x, t))


def test_strict_loading_names_a_renamed_key(tmp_path) -> None:
    cfg = SMALL_CONFIGS["tiny"]
    sd = UNetModel(cfg).state_dict()
    sd["input_blocks.1.0.in_layers.2.weightX"] = sd.pop("input_blocks.1.0.in_layers.2.weight")
    torch.save(sd, tmp_path / "bad.pt")
    with pytest.raises(CheckpointError, match=r"input_blocks\.1\.0\.in_layers\.2\.weight"):
        load_checkpoint(tmp_path / "bad.pt", cfg)


def test_strict_loading_names_a_mis_shaped_key(tmp_path) -> None:
    cfg = SMALL_CONFIGS["tiny"]
    sd = UNetModel(cfg).state_dict()
    sd["out.2.weight"] = torch.zeros(3, 8, 3, 3)
    torch.save(sd, tmp_path / "bad.pt")
    with pytest.raises(CheckpointError, match=r"out\.2\.weight"):
        load_checkpoint(tmp_path / "bad.pt", cfg)


def test_raw_state_dict_needs_a_config(tmp_path) -> None:
    torch.save(UNetModel(SMALL_CONFIGS["tiny"]).state_dict(), tmp_path / "raw.pt")
    with pytest.raises(CheckpointError, match="config"):
        load_checkpoint(tmp_path / "raw.pt")


def test_dpi_checkpoint_prefers_ema(tmp_path) -> None:
    cfg = SMALL_CONFIGS["tiny"]
    model, ema = UNetModel(cfg), UNetModel(cfg)
    torch.save({"config": cfg.to_dict(), "model": model.state_dict(), "ema": ema.state_dict(), "step": 3},
               tmp_path / "ckpt.pt")
    loaded = load_checkpoint(tmp_path / "ckpt.pt")
    assert loaded.config == cfg
    assert torch.equal(loaded.state_dict()["time_embed.0.weight"], ema.state_dict()["time_embed.0.weight"])
