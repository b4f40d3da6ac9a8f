"""Deterministic seeds for stochastic jobs, derived from their identity (scene, method, k)."""

from __future__ import annotations

import hashlib


def seed_for(*parts: object) -> int:
    """A 31-bit seed from the parts' string forms; the same parts always give the same seed."""
    digest = hashlib.sha256("/".join(str(p) for p in parts).encode()).digest()
    return int.from_bytes(digest[:4], "little") & 0x7FFFFFFF
