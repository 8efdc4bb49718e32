"""RFC 6962 / RFC 9162 (section 2.1) Merkle tree hashing over SHA-256.

A leaf's hash is ``SHA-256(0x00 || data)``, an interior node's ``SHA-256(0x01 || left ||
right)``, and the empty tree's root ``SHA-256("")``. The tree over ``n`` leaves splits at the
largest power of two below ``n`` (the left subtree is always complete).

``CompactRange`` is what a logger keeps while it appends: the roots of the complete subtrees
that make up the tree so far (one per set bit of the size), about one hash per append.
``inclusion_proof`` and ``consistency_proof`` build RFC 9162 proofs from the full list of leaf
hashes (an investigator's side, hashing each interior node at most once, without recursion);
``verify_inclusion`` and ``verify_consistency`` are the RFC's verification algorithms, and
answer False, never raise, whatever they are handed.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Iterable, Sequence

from trace_runtime.errors import MerkleError

__all__ = [
    "EMPTY_ROOT",
    "HASH_SIZE",
    "CompactRange",
    "consistency_path",
    "consistency_proof",
    "inclusion_path",
    "inclusion_proof",
    "leaf_hash",
    "node_hash",
    "root_of",
    "verify_consistency",
    "verify_inclusion",
]

HASH_SIZE = 32
_sha256 = hashlib.sha256
EMPTY_ROOT = _sha256(b"").digest()
_LEAF = b"\x00"
_NODE = b"\x01"


def leaf_hash(data: bytes) -> bytes:
    """The hash of one leaf: SHA-256(0x00 || data)."""
    return _sha256(_LEAF + data).digest()


def node_hash(left: bytes, right: bytes) -> bytes:
    """The hash of an interior node: SHA-256(0x01 || left || right)."""
    return _sha256(_NODE + left + right).digest()


class CompactRange:
    """The roots of the complete subtrees covering leaves ``[0, size)``, largest first.

    ``append`` merges equal-sized subtrees as a binary counter carries: one hash amortised
    per leaf, and ``len(hashes) == popcount(size)`` always.
    """

    __slots__ = ("_hashes", "_size")

    def __init__(self) -> None:
        self._size = 0
        self._hashes: list[bytes] = []

    @property
    def size(self) -> int:
        return self._size

    @property
    def hashes(self) -> list[bytes]:
        """A copy of the subtree roots, largest (leftmost) first."""
        return list(self._hashes)

    def append(self, leaf: bytes) -> None:
        """Add one leaf, given as its leaf hash (``leaf_hash(data)``)."""
        hashes = self._hashes
        carry = self._size
        self._size = carry + 1
        while carry & 1:
            leaf = _sha256(_NODE + hashes.pop() + leaf).digest()
            carry >>= 1
        hashes.append(leaf)

    def root(self) -> bytes:
        """The tree's root hash: the subtree roots folded from the right."""
        hashes = self._hashes
        if not hashes:
            return EMPTY_ROOT
        acc = hashes[-1]
        for i in range(len(hashes) - 2, -1, -1):
            acc = _sha256(_NODE + hashes[i] + acc).digest()
        return acc

    def state(self) -> tuple[int, list[bytes]]:
        """What to save to continue later: ``(size, hashes)``."""
        return self._size, list(self._hashes)

    @classmethod
    def restore(cls, size: int, hashes: Sequence[bytes]) -> CompactRange:
        """A compact range continuing from a saved ``state()``; checks that it can be one."""
        if isinstance(size, bool) or not isinstance(size, int) or size < 0:
            raise MerkleError(f"a compact range's size is a non-negative integer, got {size!r}")
        want = size.bit_count()
        if len(hashes) != want:
            raise MerkleError(
                f"a compact range of size {size} holds {want} hashes, got {len(hashes)}"
            )
        for h in hashes:
            if not isinstance(h, bytes) or len(h) != HASH_SIZE:
                raise MerkleError("a compact range's hashes are 32-byte SHA-256 digests")
        restored = cls()
        restored._size = size
        restored._hashes = list(hashes)
        return restored

    def __repr__(self) -> str:
        return f"CompactRange(size={self._size})"


def _split(n: int) -> int:
    """The largest power of two strictly below ``n`` (``n >= 2``)."""
    return 1 << ((n - 1).bit_length() - 1)


def _range_root(leaves: Sequence[bytes], lo: int, hi: int) -> bytes:
    """MTH of ``leaves[lo:hi]`` (non-empty), by a compact range fold: iterative, O(log n)
    memory, each interior node hashed once."""
    stack: list[bytes] = []
    for offset in range(hi - lo):
        h = leaves[lo + offset]
        carry = offset
        while carry & 1:
            h = _sha256(_NODE + stack.pop() + h).digest()
            carry >>= 1
        stack.append(h)
    acc = stack.pop()
    while stack:
        acc = _sha256(_NODE + stack.pop() + acc).digest()
    return acc


def root_of(leaf_hashes: Iterable[bytes]) -> bytes:
    """The root hash of the tree over these leaf hashes (``EMPTY_ROOT`` for none)."""
    compact = CompactRange()
    for h in leaf_hashes:
        compact.append(h)
    return compact.root()


def inclusion_proof(index: int, leaf_hashes: Sequence[bytes]) -> list[bytes]:
    """RFC 9162 section 2.1.3.1: the audit path of leaf ``index``, nearest the leaf first."""
    return inclusion_path(index, len(leaf_hashes), lambda lo, hi: _range_root(leaf_hashes, lo, hi))


def inclusion_path(index: int, size: int, subtree: Callable[[int, int], bytes]) -> list[bytes]:
    """``inclusion_proof`` in a tree of ``size`` leaves whose subtree roots (over leaves
    ``lo`` to ``hi``) ``subtree`` gives: the one walk for any store of the tree's nodes."""
    if not 0 <= index < size:
        raise MerkleError(f"leaf {index} is not in a tree of {size} leaves")
    path: list[bytes] = []  # collected from the root down, returned from the leaf up
    lo, hi = 0, size
    while hi - lo > 1:
        k = _split(hi - lo)
        if index < lo + k:
            path.append(subtree(lo + k, hi))
            hi = lo + k
        else:
            path.append(subtree(lo, lo + k))
            lo += k
    path.reverse()
    return path


def consistency_proof(old_size: int, leaf_hashes: Sequence[bytes]) -> list[bytes]:
    """RFC 9162 section 2.1.4.1: the proof that the tree of ``old_size`` leaves is a prefix
    of the tree over all ``leaf_hashes``. Empty when ``old_size`` is 0 or the whole tree."""
    return consistency_path(
        old_size, len(leaf_hashes), lambda lo, hi: _range_root(leaf_hashes, lo, hi)
    )


def consistency_path(old_size: int, size: int, subtree: Callable[[int, int], bytes]) -> list[bytes]:
    """``consistency_proof`` in a tree of ``size`` leaves whose subtree roots ``subtree``
    gives (as ``inclusion_path``)."""
    if not 0 <= old_size <= size:
        raise MerkleError(f"a tree of {size} leaves has no prefix of {old_size}")
    if old_size in (0, size):
        return []
    path: list[bytes] = []
    lo, hi, m, whole = 0, size, old_size, True
    while True:
        n = hi - lo
        if m == n:
            if not whole:
                path.append(subtree(lo, hi))
            break
        k = _split(n)
        if m <= k:
            path.append(subtree(lo + k, hi))
            hi = lo + k
        else:
            path.append(subtree(lo, lo + k))
            lo += k
            m -= k
            whole = False
    path.reverse()
    return path


def _is_size(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_hash(value: object) -> bool:
    return isinstance(value, bytes) and len(value) == HASH_SIZE


def _all_hashes(proof: object) -> bool:
    return isinstance(proof, (list, tuple)) and all(_is_hash(p) for p in proof)


def verify_inclusion(
    index: int, size: int, leaf_hash: bytes, proof: Sequence[bytes], root: bytes
) -> bool:
    """RFC 9162 section 2.1.3.2: whether ``proof`` shows leaf ``index`` (given as its leaf
    hash) in the tree of ``size`` leaves with this ``root``."""
    if not (_is_size(index) and _is_size(size) and 0 <= index < size):
        return False
    if not (_is_hash(leaf_hash) and _is_hash(root) and _all_hashes(proof)):
        return False
    fn, sn = index, size - 1
    r = leaf_hash
    for p in proof:
        if sn == 0:
            return False
        if fn & 1 or fn == sn:
            r = _sha256(_NODE + p + r).digest()
            if not fn & 1:
                while fn and not fn & 1:
                    fn >>= 1
                    sn >>= 1
        else:
            r = _sha256(_NODE + r + p).digest()
        fn >>= 1
        sn >>= 1
    return sn == 0 and r == root


def verify_consistency(
    old_size: int, new_size: int, old_root: bytes, new_root: bytes, proof: Sequence[bytes]
) -> bool:
    """RFC 9162 section 2.1.4.2: whether ``proof`` shows the tree of ``old_size`` leaves with
    ``old_root`` to be a prefix of the tree of ``new_size`` leaves with ``new_root``.

    Equal sizes are consistent with an empty proof and equal roots; the empty tree (whose
    root must be ``EMPTY_ROOT``) is a prefix of every tree, with an empty proof.
    """
    if not (_is_size(old_size) and _is_size(new_size) and 0 <= old_size <= new_size):
        return False
    if not (_is_hash(old_root) and _is_hash(new_root) and _all_hashes(proof)):
        return False
    if old_size == 0:
        return len(proof) == 0 and old_root == EMPTY_ROOT
    if old_size == new_size:
        return len(proof) == 0 and old_root == new_root
    if not proof:
        return False
    path = list(proof)
    if old_size & (old_size - 1) == 0:  # an exact power of two: the old root is a node
        path.insert(0, old_root)
    fn, sn = old_size - 1, new_size - 1
    while fn & 1:
        fn >>= 1
        sn >>= 1
    fr = sr = path[0]
    for c in path[1:]:
        if sn == 0:
            return False
        if fn & 1 or fn == sn:
            fr = _sha256(_NODE + c + fr).digest()
            sr = _sha256(_NODE + c + sr).digest()
            if not fn & 1:
                while fn and not fn & 1:
                    fn >>= 1
                    sn >>= 1
        else:
            sr = _sha256(_NODE + sr + c).digest()
        fn >>= 1
        sn >>= 1
    return fr == old_root and sr == new_root and sn == 0
