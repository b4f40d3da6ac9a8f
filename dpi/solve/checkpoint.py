"""Resumable loop state: a long loop (dps's reverse diffusion, the Adam fits) saves where it stands
every few steps, so that a job killed in the middle continues from there when rerun, not from the start.

The state is everything the remaining steps depend on: the step to continue from, the loop's
tensors (x_t, the env model's parameters, the materials), Adam's moments, the torch.Generator's
state and the trace so far. Mitsuba's seeds are derived from the run's seed and the step index,
so a continued run equals an uninterrupted one up to float rounding. The file carries a key, a
hash of what determines the run (config, seed, render settings, starting tensors): a file with
another key, or one that cannot be read, is ignored and the run starts afresh, so a run never
continues another. Files are replaced atomically: a kill while saving leaves the previous state.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from dpi.io.atomic import atomic_path
from dpi.solve.problem import InverseProblem
from dpi.solve.trace import Trace


@dataclass
class LoopState:
    """Where a loop stands before step `step`: all it needs to go on as if it had never stopped."""

    step: int
    """the next step to run (steps 0 .. step - 1 are done)"""
    tensors: dict[str, torch.Tensor]
    """the loop's variables by name (x_t, env model parameters, material textures)"""
    optimizer: dict[str, Any] | None
    """Adam's state_dict (None: nothing is optimised)"""
    generator: torch.Tensor
    """torch.Generator.get_state() of the loop's generator"""
    trace_steps: list[dict[str, Any]]
    nan_skips: int
    seconds: float
    """the trace's wall time so far"""
    snapshots: list[torch.Tensor] = field(default_factory=list)
    """dps's x0_hat frames kept so far for its progress strip"""

    @classmethod
    def capture(cls, step: int, tensors: dict[str, torch.Tensor], optimizer: torch.optim.Optimizer | None,
                generator: torch.Generator, trace: Trace, snapshots: list[torch.Tensor] | None = None) -> "LoopState":
        """The state of a running loop about to run `step`."""
        return cls(step, {name: t.detach() for name, t in tensors.items()},
                   optimizer.state_dict() if optimizer is not None else None, generator.get_state(),
                   list(trace.steps), trace.nan_skips, trace.seconds, list(snapshots or []))

    @torch.no_grad()
    def restore(self, tensors: dict[str, torch.Tensor], optimizer: torch.optim.Optimizer | None,
                generator: torch.Generator, trace: Trace) -> None:
        """Put a freshly set-up loop back where this state stood (tensors are copied in place)."""
        for name, t in tensors.items():
            t.copy_(self.tensors[name])
        if optimizer is not None:
            optimizer.load_state_dict(self.optimizer)
        generator.set_state(self.generator)
        trace.steps, trace.nan_skips = list(self.trace_steps), self.nan_skips
        trace.started = time.perf_counter() - self.seconds


def update_key(digest: Any, part: Any) -> None:
    """Feed one part of a run's identity into a hash: tensors by dtype, shape and bytes, dicts and
    sequences item by item, anything else by its repr."""
    if isinstance(part, torch.Tensor):
        t = part.detach().cpu().contiguous().reshape(-1)
        digest.update(f"tensor {t.dtype} {tuple(part.shape)}:".encode())
        digest.update(t.view(torch.uint8).numpy())
    elif isinstance(part, dict):
        for name in sorted(part, key=str):
            digest.update(f"{name!r}=".encode())
            update_key(digest, part[name])
    elif isinstance(part, (list, tuple)):
        digest.update(f"{len(part)} items:".encode())
        for item in part:
            update_key(digest, item)
    else:
        digest.update(f"{part!r};".encode())


def run_key(*parts: Any) -> str:
    """A hash of everything that determines a run (configs, seeds, starting tensors)."""
    digest = hashlib.sha256()
    update_key(digest, parts)
    return digest.hexdigest()


def problem_identity(problem: InverseProblem) -> dict[str, Any]:
    """What of the inverse problem a run's result depends on besides its starting tensors: views, their
    exposure, unknowns' resolution, loss space and the renderer's sampling (not its thread count)."""
    render = problem.renderer.settings
    return {"views": [v.name for v in problem.views], "exposure": problem.exposure, "settings": vars(problem.settings),
            "spp": render.spp, "max_depth": render.max_depth}


@dataclass
class Checkpoint:
    """The resume file of one run (`key`), written every `every` steps of its loop."""

    path: Path
    key: str
    every: int

    def load(self) -> LoopState | None:
        """This run's saved state; None (saying why in one line) when the file is missing, unreadable
        or another run's."""
        if not self.path.is_file():
            return None
        try:
            saved = torch.load(self.path, weights_only=True)
            key = saved.pop("key")
            state = LoopState(**saved)
        except Exception as error:  # a truncated or foreign file is no reason to fail the job
            reason = str(error).partition("\n")[0][:120]
            print(f"resume: ignoring unreadable {self.path} ({type(error).__name__}: {reason}); starting afresh",
                  flush=True)
            return None
        if key != self.key:
            print(f"resume: ignoring {self.path}, saved by a different run (config, seed or start); starting afresh",
                  flush=True)
            return None
        print(f"resume: continuing from step {state.step} ({self.path})", flush=True)
        return state

    def resume(self, tensors: dict[str, torch.Tensor], optimizer: torch.optim.Optimizer | None,
               generator: torch.Generator, trace: Trace) -> LoopState | None:
        """Restore a freshly set-up loop from this run's saved state, if any; returns that state (None:
        start afresh). The trace's info says from which step the run continued (None: it did not)."""
        state = self.load()
        if state is not None:
            state.restore(tensors, optimizer, generator, trace)
        trace.info["resumed_from_step"] = state.step if state is not None else None
        return state

    def due(self, step: int, start: int) -> bool:
        """Whether to save before `step`: every `every` steps, except where this run started."""
        return step != start and step % self.every == 0

    def save(self, state: LoopState) -> None:
        """Write the state atomically (torch.save to a temporary sibling, then rename)."""
        with atomic_path(self.path) as tmp:
            torch.save({"key": self.key, **vars(state)}, tmp)

    def remove(self) -> None:
        """Delete the file once the run has finished (a later rerun is a new run)."""
        self.path.unlink(missing_ok=True)


def checkpoint_for(path: str | Path | None, every: int, *run: Any) -> Checkpoint | None:
    """The resume file at `path` of the run that `run` identifies (hashed into its key); None without a path."""
    return Checkpoint(Path(path), run_key(*run), every) if path is not None else None
