"""Faults on disk after a job wrote its files: a cached intermediate that no longer reads is named with how to
rebuild it, in one line, instead of a reader's traceback in the next job."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from dpi.io.exr import write_exr
from dpi.solve.problem import CachedFileError, InverseProblem, ProblemConfig


def test_a_cached_init_damaged_on_disk_is_named_with_how_to_rebuild_it(tmp_path):
    init = tmp_path / "results" / "scene" / "init"
    write_exr(init / "envmap.exr", np.ones((4, 8, 3), np.float32))
    for name in ("albedo", "roughness", "metallic"):
        write_exr(init / f"{name}.exr", np.full((8, 8, 3 if name == "albedo" else 1), 0.5, np.float32))
    problem = SimpleNamespace(settings=ProblemConfig(env_height=4, texture_size=8), to_solver_units=lambda d: d)
    InverseProblem.load_decomposition(problem, init)  # reads while intact
    data = (init / "envmap.exr").read_bytes()
    (init / "envmap.exr").write_bytes(data[: len(data) // 2])
    with pytest.raises(CachedFileError, match=r"envmap.exr: .*delete the folder .*init and run the workflow again") \
            as info:
        InverseProblem.load_decomposition(problem, init)
    assert "\n" not in str(info.value)
