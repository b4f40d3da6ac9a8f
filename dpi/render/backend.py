"""Mitsuba / Dr.Jit / PyTorch backend set-up: LLVM discovery, variant choice, thread counts.

Mitsuba's CPU variant (`llvm_ad_rgb`) needs libLLVM >= 16; older versions abort inside the JIT
("Cannot select: fminimum"). Dr.Jit reads `DRJIT_LIBLLVM_PATH` when it is first imported, so
`mitsuba()` must run before any other module imports Mitsuba.
"""

from __future__ import annotations

import glob
import os
import re
from typing import Any

MIN_LLVM = 16
LLVM_SEARCH_GLOBS = (
    "/usr/lib/x86_64-linux-gnu/libLLVM-*.so",
    "/usr/lib/x86_64-linux-gnu/libLLVM.so.*",
    "/usr/lib/aarch64-linux-gnu/libLLVM-*.so",
    "/usr/lib/aarch64-linux-gnu/libLLVM.so.*",
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
    "/usr/local/lib/libLLVM*.so*",
    "/opt/homebrew/opt/llvm/lib/libLLVM.dylib",
)


class BackendError(RuntimeError):
    """No usable Mitsuba backend could be set up."""


def llvm_major(path: str) -> int | None:
    """LLVM major version encoded in a libLLVM file name, or None."""
    match = re.search(r"libLLVM(?:-|\.so\.)(\d+)", os.path.basename(path))
    if match is None:
        match = re.search(r"llvm-(\d+)", path)
    return int(match.group(1)) if match else None


def find_libllvm(globs: tuple[str, ...] | None = None) -> str | None:
    """Newest libLLVM >= 16 matching `globs` (default: the usual system locations), or None."""
    found = {p for g in (globs or LLVM_SEARCH_GLOBS) for p in glob.glob(g)}
    usable = [(llvm_major(p), p) for p in found if (llvm_major(p) or 0) >= MIN_LLVM]
    return max(usable)[1] if usable else None


def configure_llvm() -> str:
    """Point Dr.Jit at a usable libLLVM (keeps a valid user setting); returns the path."""
    given = os.environ.get("DRJIT_LIBLLVM_PATH")
    if given and os.path.exists(given) and (llvm_major(given) or MIN_LLVM) >= MIN_LLVM:
        return given
    path = find_libllvm()
    if path is None:
        raise BackendError(
            "Mitsuba's CPU backend needs libLLVM >= 16 and none was found. "
            "Install it with `apt-get install libllvm19` (Debian/Ubuntu) or set "
            "DRJIT_LIBLLVM_PATH to a libLLVM-16+ shared library."
        )
    os.environ["DRJIT_LIBLLVM_PATH"] = path
    return path


def cuda_usable() -> bool:
    """True when a CUDA device is visible to PyTorch (a proxy for Dr.Jit's CUDA backend)."""
    try:
        import torch
    except ImportError:  # pragma: no cover - torch is a hard dependency
        return False
    return bool(torch.cuda.is_available())


def choose_variant(prefer: str = "auto") -> str:
    """`cuda_ad_rgb` when a GPU works (or is asked for), else `llvm_ad_rgb`."""
    if prefer not in ("auto", "cuda_ad_rgb", "llvm_ad_rgb"):
        raise BackendError(f"unknown Mitsuba variant {prefer!r}; use auto, cuda_ad_rgb or llvm_ad_rgb")
    if prefer == "auto":
        return "cuda_ad_rgb" if cuda_usable() else "llvm_ad_rgb"
    return prefer


def set_threads(threads: int) -> None:
    """Use exactly `threads` CPU threads in torch, Dr.Jit and OpenCV (Snakemake's `threads`): the one place a job's
    thread count is set."""
    import cv2
    import drjit as dr
    import torch

    threads = max(1, int(threads))
    torch.set_num_threads(threads)
    dr.set_thread_count(threads)
    cv2.setNumThreads(threads)


def mitsuba(variant: str = "auto", threads: int | None = None) -> Any:
    """Import Mitsuba with a working variant and thread count; returns the `mitsuba` module."""
    chosen = choose_variant(variant)
    if chosen.startswith("llvm"):
        configure_llvm()
    import mitsuba as mi

    if mi.variant() != chosen:
        try:
            mi.set_variant(chosen)
        except Exception as exc:  # Dr.Jit raises plain exceptions for backend failures
            raise BackendError(f"could not start Mitsuba variant {chosen}: {exc}") from exc
    if threads is not None:
        set_threads(threads)
    return mi
