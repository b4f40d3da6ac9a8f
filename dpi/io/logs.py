"""Sending a job's progress output (tqdm, prints, warnings) to its per-rule log file."""

from __future__ import annotations

import sys
import traceback
from contextlib import contextmanager, redirect_stderr, redirect_stdout
from pathlib import Path
from typing import Iterator


@contextmanager
def log_to(path: str | Path | None, one_line: tuple[type[Exception], ...] = ()) -> Iterator[None]:
    """Redirect stdout and stderr into `path` (appending) for the block; no-op for None.

    An exception of a `one_line` type (an input error whose message names the file and what to fix, as
    `dpi validate` prints it) ends the job with that line alone, in the log and on stderr, and exit status 1;
    any other exception goes to the log with its traceback and propagates."""
    if path is None:
        yield
        return
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a", buffering=1) as log, redirect_stdout(log), redirect_stderr(log):
        try:
            yield
            return
        except one_line as exc:
            message = str(exc)
            print(message, file=sys.stderr)
        except Exception:
            traceback.print_exc(file=sys.stderr)
            raise
    sys.exit(message)
