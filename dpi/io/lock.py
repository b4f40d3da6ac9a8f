"""One writer per results folder: an advisory lock on `results_dir/.dpi.lock`, held for the life of the process.

Snakemake locks its own working directory; two runs started from two working directories on one results_dir
would both run every job, and a second run from the same one would meet the first's unfinished files. The lock lives
with the results and is asked for when the workflow is read, so a second run from anywhere is refused with one
line, and the kernel releases it when the holder exits, even on kill -9 (a stale lock file holds nothing).
"""

from __future__ import annotations

import fcntl
import os
import re
import stat
from pathlib import Path

LOCK_NAME = ".dpi.lock"
_held: dict[Path, int] = {}


class ResultsLocked(RuntimeError):
    """Another process holds the results folder's lock."""


def lock_results(results: str | os.PathLike) -> Path:
    """Hold the lock of `results` (created when missing) until this process exits; a second call in the same
    process is a no-op. Raises ResultsLocked naming the holder's process and working directory."""
    folder = Path(results).resolve()
    if folder in _held:
        return folder / LOCK_NAME
    if folder.exists() and not folder.is_dir():
        raise ResultsLocked(f"{folder}: results_dir is a file, not a folder; choose another results_dir")
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / LOCK_NAME
    try:  # O_NONBLOCK: a FIFO in its place opens at once (and is refused below) instead of waiting for a writer
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK, 0o666)
    except OSError as exc:
        raise ResultsLocked(f"{path}: cannot open the results lock ({exc.strerror}); remove it if it is not a "
                            "plain file") from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise ResultsLocked(f"{path}: the results lock is not a plain file; remove it")
    take_or_refuse(fd, folder)
    os.ftruncate(fd, 0)
    os.write(fd, f"pid {os.getpid()}\n".encode())
    _held[folder] = fd
    return path


def take_or_refuse(fd: int, folder: Path) -> None:
    """flock the open lock file `fd`, or close it and raise ResultsLocked naming the holder."""
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        pid = re.match(rb"pid (\d{1,10})\b", os.read(fd, 64))
        os.close(fd)
        holder = f"process {int(pid.group(1))}" if pid else "another process"
        raise ResultsLocked(f"{folder}: another dpi run ({holder}) is writing here; wait for it to finish, or use "
                            "another results_dir") from None


def check_unlocked(results: str | os.PathLike) -> None:
    """Raise ResultsLocked when another process holds the lock of `results`, taking nothing: the workflow asks before
    Snakemake reads the results folder, whose files a running job is still writing (Snakemake would call them
    incomplete and advise a rerun)."""
    folder = Path(results).resolve()
    path = folder / LOCK_NAME
    if folder in _held or not path.is_file() or path.is_symlink():
        return
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return  # lock_results says what is wrong with it
    take_or_refuse(fd, folder)
    fcntl.flock(fd, fcntl.LOCK_UN)
    os.close(fd)
