"""The per-cycle hash chain: each seal names the digests of its cycle's layer messages and
the digest of the previous seal, so any change, removal or reordering breaks a link."""

from __future__ import annotations

import hashlib

from trace_runtime.records import GENESIS

__all__ = ["GENESIS", "digest"]


def digest(data: bytes) -> str:
    """SHA-256 hex digest of a message's data (its canonical bytes)."""
    return hashlib.sha256(data).hexdigest()
