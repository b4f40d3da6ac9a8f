"""The job record every stage takes: which scene, method and sample, the resolved pipeline (settings and
`dpi.io.layout` paths), and the threads the job may use. The rules, the `dpi` command and the study engine
build it the same way and hand it to the same stage functions."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

from dpi.config.pipeline import Pipeline
from dpi.io.layout import INIT, SceneLayout
from dpi.solve.problem import SolveConfig


@dataclass(frozen=True)
class StageJob:
    """One job of a stage. `scene` is None for a run-wide stage (summary, report), `family` names a prior's
    family for the prior stages; `label` is the sample's folder when it is not the method's name (a study's
    dps variant); `progress` shows bars (off in studies and tests)."""

    pipeline: Pipeline
    scene: str | None = None
    method: str = INIT
    k: int = 0
    threads: int = 1
    family: str | None = None
    label: str | None = None
    progress: bool = True

    @property
    def config(self) -> dict[str, Any]:
        return self.pipeline.config

    @cached_property
    def paths(self) -> SceneLayout:
        """The scene's folder of results (dpi.io.layout)."""
        if self.scene is None:
            raise ValueError("a run-wide job has no scene paths")
        return self.pipeline.layout.scene(self.scene)

    @property
    def capture_dir(self) -> Path:
        return self.pipeline.layout.capture_dir(self.scene)

    @property
    def folder(self) -> str:
        """The sample's folder name under the scene: the label, else the method."""
        return self.label or self.method

    @property
    def sample_dir(self) -> Path:
        """Where the job's decomposition is (the init's folder for the init)."""
        return self.paths.sample_dir(self.folder, self.k)

    @property
    def evaluation(self) -> Path:
        """The job's metrics file."""
        return self.paths.evaluation(self.folder, self.k)

    @property
    def evaluation_views(self) -> Path:
        """The job's held-out re-renders."""
        return self.paths.evaluation_views(self.folder, self.k)

    @cached_property
    def given(self) -> dict[str, bool]:
        """What the scene's capture gives (cameras, masks, mesh, mesh_has_uv), read once a job."""
        return self.pipeline.given(self.scene)

    @cached_property
    def solve(self) -> SolveConfig:
        """Renderer and problem settings on the job's threads."""
        return self.pipeline.solve_settings(self.threads)


def rule_job(snakemake: Any) -> StageJob:
    """The job record of a running Snakemake rule: its resolved config (rules/common.smk resolves it), its
    wildcards (scene, method, k, family, where the rule has them) and its threads."""
    w = snakemake.wildcards
    return StageJob(Pipeline(snakemake.config), scene=getattr(w, "scene", None), method=getattr(w, "method", INIT),
                    k=int(getattr(w, "k", 0)), threads=snakemake.threads, family=getattr(w, "family", None))
