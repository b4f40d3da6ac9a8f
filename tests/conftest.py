"""Shared fixtures: a tiny synthetic capture (rendered once per session) and Mitsuba set-up."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

os.environ.setdefault("OMP_NUM_THREADS", "2")

TINY_SYNTH = dict(shape="blob", views=5, held_out_every=5, width=24, height=24, spp=32, env_height=8,
                  texture_size=16, seed=3)


@pytest.fixture(scope="session")
def mi():
    """The mitsuba module with dpi's variant selection (llvm_ad_rgb on CPU)."""
    from dpi.render.backend import mitsuba

    return mitsuba(threads=2)


@pytest.fixture(scope="session")
def tiny_capture(tmp_path_factory, mi) -> Path:
    """A 5-view 24x24 synthetic capture with ground truth (one view held out)."""
    from dpi.synth.capture import SynthConfig, make_synthetic_capture

    root = tmp_path_factory.mktemp("captures") / "tiny"
    make_synthetic_capture(root, SynthConfig(**TINY_SYNTH), threads=2, progress=False)
    return root


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The slow tests first: under xdist's loadscope (make test) each module runs on one worker, its module fixtures
    (often a whole workflow run) built once, and the end-to-end modules handed out before the quick ones, so the last
    worker to finish is not the one that drew an end-to-end run at the end."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
