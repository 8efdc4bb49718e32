"""A robot's whole tree held in memory, so many proofs over one log stay cheap.

``trace_runtime.tlog.merkle``'s proofs hash every leaf of the subtrees they name (O(n) each):
right for one proof, but ``witness push`` of a day's log (864,000 leaves, 8,640
checkpoints) would hash billions of times. ``LevelTree`` hashes each complete aligned
subtree once (n - 1 hashes in all); any RFC 6962 subtree root is then O(log n) of them,
and its proofs are the same as ``merkle.inclusion_proof`` / ``consistency_proof`` (the same
recursion, pinned to them by tests/trace_audit/witness/test_tree.py).
"""

from __future__ import annotations

from collections.abc import Sequence

from trace_runtime.errors import MerkleError
from trace_runtime.tlog.merkle import (
    EMPTY_ROOT,
    consistency_path,
    inclusion_path,
    node_hash,
)

__all__ = ["LevelTree"]


def _split(n: int) -> int:
    """The largest power of two below ``n`` (n > 1)."""
    return 1 << ((n - 1).bit_length() - 1)


class LevelTree:
    """Every complete aligned subtree's hash of a list of leaf hashes."""

    def __init__(self, leaves: Sequence[bytes]) -> None:
        self.levels: list[list[bytes]] = [list(leaves)]
        level = self.levels[0]
        while len(level) > 1:
            level = [node_hash(level[i], level[i + 1]) for i in range(0, len(level) - 1, 2)]
            self.levels.append(level)

    @property
    def size(self) -> int:
        return len(self.levels[0])

    def _range(self, lo: int, hi: int) -> bytes:
        n = hi - lo
        if n & (n - 1) == 0 and lo % n == 0:
            return self.levels[n.bit_length() - 1][lo // n]
        k = _split(n)
        return node_hash(self._range(lo, lo + k), self._range(lo + k, hi))

    def root(self, size: int) -> bytes:
        """The root of the tree of the first ``size`` leaves."""
        if not 0 <= size <= self.size:
            raise MerkleError(f"a tree of {self.size} leaves has no prefix of {size}")
        return EMPTY_ROOT if size == 0 else self._range(0, size)

    def inclusion_proof(self, index: int, size: int) -> list[bytes]:
        """RFC 9162 §2.1.3.1: leaf ``index`` in the tree of ``size`` leaves."""
        if size > self.size:
            raise MerkleError(f"leaf {index} is not in a tree of {size} leaves")
        return inclusion_path(index, size, self._range)

    def consistency_proof(self, old_size: int, size: int) -> list[bytes]:
        """RFC 9162 §2.1.4.1: the tree of ``old_size`` leaves is a prefix of ``size``'s."""
        if size > self.size:
            raise MerkleError(f"a tree of {size} leaves has no prefix of {old_size}")
        return consistency_path(old_size, size, self._range)
