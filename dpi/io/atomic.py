"""Atomic file output: write to a temporary sibling, rename on success.

A killed job therefore never leaves a half-written file under its final name; a folder of outputs (an export) is
written in a temporary sibling and moved in whole. The file gets the mode a plain
`open` would give it (0666 less the umask), not the temporary file's private 0600, so a group can share a
results folder.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator


def umask() -> int:
    """The process's file-mode creation mask (read by setting it and putting it back)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path next to `path`; move it onto `path` only if the block succeeds."""
    final = Path(path)
    final.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{final.stem}.", suffix=final.suffix, dir=final.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~umask())
        os.replace(tmp, final)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def write_json(path: str | os.PathLike, data: Any) -> None:
    """Write `data` as indented JSON atomically; NaN/Inf are rejected, never written."""
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2, allow_nan=False) + "\n")


def write_text(path: str | os.PathLike, text: str) -> None:
    """Write a text file atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


class OutputError(ValueError):
    """An output path the workflow would write lies outside results_dir or runs through a link; the message names
    it."""


def link_error(path: Path) -> OutputError:
    """The error naming a link on the way to the workflow's outputs."""
    return OutputError(f"{path}: is a link (to {os.readlink(path)}) inside results_dir; dpi writes its outputs inside "
                       "results_dir only: remove the link")


def inside_results(path: str | os.PathLike, results: str | os.PathLike) -> Path:
    """`path` when it lies inside `results` and neither it nor a folder between them is a link (else OutputError):
    the workflow writes nothing through a link to elsewhere on the host."""
    path, results = Path(path).absolute(), Path(results).absolute()
    if not path.is_relative_to(results):
        raise OutputError(f"{path}: lies outside results_dir {results}")
    for part in [path, *path.parents]:
        if part == results:
            break
        if part.is_symlink():
            raise link_error(part)
    if not path.resolve().is_relative_to(results.resolve()):
        raise OutputError(f"{path}: resolves outside results_dir {results}")
    return path


def check_no_links(results: str | os.PathLike) -> None:
    """OutputError naming the first link inside `results` (none when it does not exist yet): the workflow writes
    under results_dir only, and a link there would lead its outputs elsewhere on the host."""
    for folder, dirs, files in os.walk(results):
        for name in [*dirs, *files]:
            path = Path(folder) / name
            if path.is_symlink():
                raise link_error(path)


@contextmanager
def replaced_folder(target: str | os.PathLike, results: str | os.PathLike) -> Iterator[Path]:
    """Yield an empty temporary folder beside `target` (checked by `inside_results`); when the block succeeds it
    replaces `target` whole, when it fails it is removed: a failed write leaves neither a partial folder nor stray
    files."""
    final = inside_results(target, results)
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.", dir=final.parent))
    try:
        yield tmp
        os.chmod(tmp, 0o777 & ~umask())
        inside_results(final, results)  # not turned into a link meanwhile
        if final.is_dir():
            shutil.rmtree(final)
        elif final.exists():
            final.unlink()
        os.replace(tmp, final)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
