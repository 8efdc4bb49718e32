"""The per-cycle hash chain: each seal names the digests of its cycle's layer messages and
the digest of the previous seal, so any change, removal or reordering breaks a link.

This is the chain's primitive, below the reader's ``Cycle``; the check of one cycle against
its seal, built on it, is ``trace_runtime.seal_check.verify_cycle``.
"""

from __future__ import annotations

import hashlib

from trace_runtime.records import GENESIS

__all__ = ["GENESIS", "digest"]


def digest(data: bytes) -> str:
    """SHA-256 hex digest of a message's data (its canonical bytes)."""
    return hashlib.sha256(data).hexdigest()
