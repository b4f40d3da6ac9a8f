"""Per-step trace of an optimisation or sampling run, written next to its outputs as trace.json."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dpi.io.atomic import write_json


@dataclass
class Trace:
    """Records one dict per step (loss, timings, ...) plus run-level information."""

    info: dict[str, Any] = field(default_factory=dict)
    steps: list[dict[str, Any]] = field(default_factory=list)
    nan_skips: int = 0
    started: float = field(default_factory=time.perf_counter)

    def record(self, **values: Any) -> None:
        """Append one step; non-finite floats are stored as None (JSON has no NaN)."""
        self.steps.append({k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                           for k, v in values.items()})

    def skip(self, step: int, reason: str) -> None:
        """Count a skipped update (NaN/Inf in loss or gradients) and record why."""
        self.nan_skips += 1
        self.record(step=step, skipped=reason)

    @property
    def seconds(self) -> float:
        """Wall time since the trace was started."""
        return time.perf_counter() - self.started

    def summary(self) -> dict[str, Any]:
        """Run-level summary: steps, NaN skips, wall time, final loss."""
        losses = [s["loss"] for s in self.steps if s.get("loss") is not None]
        return {"steps": len(self.steps), "nan_skips": self.nan_skips, "seconds": round(self.seconds, 3),
                "final_loss": losses[-1] if losses else None}

    def save(self, path: str | Path) -> None:
        """Write info, summary and steps as JSON (atomically)."""
        write_json(path, {"info": self.info, "summary": self.summary(), "steps": self.steps})
