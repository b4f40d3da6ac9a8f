"""Sending a job's progress output (tqdm, prints, warnings) to its per-rule log file."""

from __future__ import annotations

import sys
import traceback
from contextlib import contextmanager, redirect_stderr, redirect_stdout
from pathlib import Path
from typing import Iterator


@contextmanager
def log_to(path: str | Path | None) -> Iterator[None]:
    """Redirect stdout and stderr into `path` (appending) for the block; no-op for None."""
    if path is None:
        yield
        return
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a", buffering=1) as log, redirect_stdout(log), redirect_stderr(log):
        try:
            yield
        except Exception:
            traceback.print_exc(file=sys.stderr)
            raise
