"""Stage job records for tests, built as the rules build them: the resolved config with a test's folders and
settings merged over it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from dpi.stages import INIT, Pipeline, StageJob, resolve_config


def stage_job(capture: Path, results: Path, method: str = INIT, k: int = 0, threads: int = 2,
              **settings: Any) -> StageJob:
    """The job of capture folder `capture` (its name is the scene, its parent captures_dir), results under
    `results`, with `settings` (config sections) merged over the resolved config."""
    config = resolve_config({"captures_dir": str(capture.parent), "results_dir": str(results),
                             "scenes": [capture.name], **settings})
    return StageJob(Pipeline(config), capture.name, method, k, threads, progress=False)
