"""trace_runtime.tlog.merkle against RFC 9162's definitions written out literally (MTH, PATH,
PROOF/SUBPROOF, recursive and naive), and against Certificate Transparency's published
reference vectors (certificate-transparency's merkle_tree_test.cc: the eight inputs, the
roots of their prefixes, some audit paths and consistency proofs)."""

from __future__ import annotations

import hashlib
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trace_runtime.errors import MerkleError
from trace_runtime.tlog.merkle import (
    EMPTY_ROOT,
    CompactRange,
    consistency_proof,
    inclusion_proof,
    leaf_hash,
    node_hash,
    root_of,
    verify_consistency,
    verify_inclusion,
)

# ---- the naive reference: RFC 9162 section 2.1, recursion as the RFC writes it ----


def _h(data: bytes) -> bytes:
    return hashlib.sha256(data).digest()


def _k(n: int) -> int:
    k = 1
    while k * 2 < n:
        k *= 2
    return k


def ref_mth(d: list[bytes]) -> bytes:
    """MTH(D[n]) over the leaves' data."""
    if not d:
        return _h(b"")
    if len(d) == 1:
        return _h(b"\x00" + d[0])
    k = _k(len(d))
    return _h(b"\x01" + ref_mth(d[:k]) + ref_mth(d[k:]))


def ref_path(m: int, d: list[bytes]) -> list[bytes]:
    """PATH(m, D[n])."""
    if len(d) == 1:
        return []
    k = _k(len(d))
    if m < k:
        return [*ref_path(m, d[:k]), ref_mth(d[k:])]
    return [*ref_path(m - k, d[k:]), ref_mth(d[:k])]


def ref_subproof(m: int, d: list[bytes], b: bool) -> list[bytes]:
    """SUBPROOF(m, D[n], b)."""
    n = len(d)
    if m == n:
        return [] if b else [ref_mth(d)]
    k = _k(n)
    if m <= k:
        return [*ref_subproof(m, d[:k], b), ref_mth(d[k:])]
    return [*ref_subproof(m - k, d[k:], False), ref_mth(d[:k])]


def ref_proof(m: int, d: list[bytes]) -> list[bytes]:
    """PROOF(m, D[n]) for 0 < m < n."""
    return ref_subproof(m, d, True)


def data_of(n: int, salt: int = 0) -> list[bytes]:
    return [b"leaf-%d-%d" % (salt, i) for i in range(n)]


def flips(proof: list[bytes]) -> list[list[bytes]]:
    """Every proof that differs from ``proof`` in exactly one bit."""
    out = []
    for j, p in enumerate(proof):
        for bit in range(len(p) * 8):
            q = bytearray(p)
            q[bit // 8] ^= 1 << (bit % 8)
            out.append([*proof[:j], bytes(q), *proof[j + 1 :]])
    return out


SMALL = range(71)

# ---- known answers: Certificate Transparency's reference test data ----

CT_INPUTS = [
    b"",
    b"\x00",
    b"\x10",
    b"\x20\x21",
    b"\x30\x31",
    b"\x40\x41\x42\x43",
    b"\x50\x51\x52\x53\x54\x55\x56\x57",
    b"\x60\x61\x62\x63\x64\x65\x66\x67\x68\x69\x6a\x6b\x6c\x6d\x6e\x6f",
]
CT_ROOTS = [
    "6e340b9cffb37a989ca544e6bb780a2c78901d3fb33738768511a30617afa01d",
    "fac54203e7cc696cf0dfcb42c92a1d9dbaf70ad9e621f4bd8d98662f00e3c125",
    "aeb6bcfe274b70a14fb067a5e5578264db0fa9b51af5e0ba159158f329e06e77",
    "d37ee418976dd95753c1c73862b9398fa2a2cf9b4ff0fdfe8b30cd95209614b7",
    "4e3bbb1f7b478dcfe71fb631631519a3bca12c9aefca1612bfce4c13a86264d4",
    "76e67dadbcdf1e10e1b74ddc608abd2f98dfb16fbce75277b5232a127f2087ef",
    "ddb89be403809e325750d3d263cd78929c2942b7942a34b77e122c9594a74c8c",
    "5dc9da79a70659a9ad559cb701ded9a2ab9d823aad2f4960cfe370eff4604328",
]
# (0-based leaf index, tree size, audit path); CT numbers leaves from 1
CT_PATHS = [
    (
        0,
        8,
        [
            "96a296d224f285c67bee93c30f8a309157f0daa35dc5b87e410b78630a09cfc7",
            "5f083f0a1a33ca076a95279832580db3e0ef4584bdff1f54c8a360f50de3031e",
            "6b47aaf29ee3c2af9af889bc1fb9254dabd31177f16232dd6aab035ca39bf6e4",
        ],
    ),
    (
        5,
        8,
        [
            "bc1a0643b12e4d2d7c77918f44e0f4f79a838b6cf9ec5b5c283e1f4d88599e6b",
            "ca854ea128ed050b41b35ffc1b87b8eb2bde461e9e3b5596ece6b9d5975a0ae0",
            "d37ee418976dd95753c1c73862b9398fa2a2cf9b4ff0fdfe8b30cd95209614b7",
        ],
    ),
    (2, 3, ["fac54203e7cc696cf0dfcb42c92a1d9dbaf70ad9e621f4bd8d98662f00e3c125"]),
    (
        1,
        5,
        [
            "6e340b9cffb37a989ca544e6bb780a2c78901d3fb33738768511a30617afa01d",
            "5f083f0a1a33ca076a95279832580db3e0ef4584bdff1f54c8a360f50de3031e",
            "bc1a0643b12e4d2d7c77918f44e0f4f79a838b6cf9ec5b5c283e1f4d88599e6b",
        ],
    ),
    (0, 1, []),
]
CT_PROOFS = [
    (1, 1, []),
    (
        1,
        8,
        [
            "96a296d224f285c67bee93c30f8a309157f0daa35dc5b87e410b78630a09cfc7",
            "5f083f0a1a33ca076a95279832580db3e0ef4584bdff1f54c8a360f50de3031e",
            "6b47aaf29ee3c2af9af889bc1fb9254dabd31177f16232dd6aab035ca39bf6e4",
        ],
    ),
    (
        6,
        8,
        [
            "0ebc5d3437fbe2db158b9f126a1d118e308181031d0a949f8dededebc558ef6a",
            "ca854ea128ed050b41b35ffc1b87b8eb2bde461e9e3b5596ece6b9d5975a0ae0",
            "d37ee418976dd95753c1c73862b9398fa2a2cf9b4ff0fdfe8b30cd95209614b7",
        ],
    ),
    (
        2,
        5,
        [
            "5f083f0a1a33ca076a95279832580db3e0ef4584bdff1f54c8a360f50de3031e",
            "bc1a0643b12e4d2d7c77918f44e0f4f79a838b6cf9ec5b5c283e1f4d88599e6b",
        ],
    ),
]
CT_LEAVES = [leaf_hash(x) for x in CT_INPUTS]


def test_hash_primitives_are_the_rfc_s() -> None:
    assert EMPTY_ROOT.hex() == "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855"
    assert root_of([]) == EMPTY_ROOT == CompactRange().root()
    assert leaf_hash(b"abc") == _h(b"\x00abc")
    assert node_hash(b"l" * 32, b"r" * 32) == _h(b"\x01" + b"l" * 32 + b"r" * 32)


@pytest.mark.parametrize("n", range(1, 9))
def test_certificate_transparency_roots(n: int) -> None:
    assert root_of(CT_LEAVES[:n]).hex() == CT_ROOTS[n - 1]
    compact = CompactRange()
    for h in CT_LEAVES[:n]:
        compact.append(h)
    assert compact.root().hex() == CT_ROOTS[n - 1]


@pytest.mark.parametrize(("index", "size", "path"), CT_PATHS)
def test_certificate_transparency_paths(index: int, size: int, path: list[str]) -> None:
    proof = inclusion_proof(index, CT_LEAVES[:size])
    assert [p.hex() for p in proof] == path
    root = bytes.fromhex(CT_ROOTS[size - 1])
    assert verify_inclusion(index, size, CT_LEAVES[index], proof, root)


@pytest.mark.parametrize(("old", "new", "path"), CT_PROOFS)
def test_certificate_transparency_consistency(old: int, new: int, path: list[str]) -> None:
    proof = consistency_proof(old, CT_LEAVES[:new])
    assert [p.hex() for p in proof] == path
    old_root, new_root = (bytes.fromhex(CT_ROOTS[s - 1]) for s in (old, new))
    assert verify_consistency(old, new, old_root, new_root, proof)


# ---- every size up to 70, exhaustively, against the naive reference ----


@pytest.mark.parametrize("n", SMALL)
def test_roots_and_compact_range_after_every_append(n: int) -> None:
    d = data_of(n)
    leaves = [leaf_hash(x) for x in d]
    assert root_of(leaves) == ref_mth(d)
    compact = CompactRange()
    for i, h in enumerate(leaves):
        compact.append(h)
        assert compact.size == i + 1
        assert len(compact.hashes) == (i + 1).bit_count()
        assert compact.root() == ref_mth(d[: i + 1])
        size, hashes = compact.state()
        again = CompactRange.restore(size, hashes)
        assert again.root() == compact.root()
    # a restored range continues exactly as the original would have
    for cut in range(n + 1):
        head = CompactRange()
        for h in leaves[:cut]:
            head.append(h)
        resumed = CompactRange.restore(*head.state())
        for h in leaves[cut:]:
            resumed.append(h)
        assert resumed.root() == ref_mth(d)
        assert resumed.state() == (n, _compact_of(leaves))


def _compact_of(leaves: list[bytes]) -> list[bytes]:
    """The subtree roots a compact range of these leaves holds, from the reference: one per
    set bit of the size, largest first."""
    out, lo, n = [], 0, len(leaves)
    for bit in range(n.bit_length() - 1, -1, -1):
        if n >> bit & 1:
            out.append(ref_mth_leaves(leaves[lo : lo + (1 << bit)]))
            lo += 1 << bit
    return out


def ref_mth_leaves(leaves: list[bytes]) -> bytes:
    if len(leaves) == 1:
        return leaves[0]
    k = _k(len(leaves))
    return _h(b"\x01" + ref_mth_leaves(leaves[:k]) + ref_mth_leaves(leaves[k:]))


@pytest.mark.parametrize("n", range(1, 71))
def test_inclusion_proofs_for_every_leaf(n: int) -> None:
    d = data_of(n)
    leaves = [leaf_hash(x) for x in d]
    root = ref_mth(d)
    for i in range(n):
        proof = inclusion_proof(i, leaves)
        assert proof == ref_path(i, d)
        assert verify_inclusion(i, n, leaves[i], proof, root)
        for j in range(n + 2):
            if j != i:
                assert not verify_inclusion(j, n, leaves[i], proof, root)
        for m in range(n + 3):
            if m != n:
                # A proof binds the tree size only through its shape (the signed checkpoint
                # binds the size): another size whose audit path has the same length takes
                # the same path through the tree, and verifies; every other size fails.
                same_shape = i < m and len(ref_path(i, data_of(m))) == len(proof)
                assert verify_inclusion(i, m, leaves[i], proof, root) == same_shape
        assert not verify_inclusion(i, n, leaves[(i + 1) % n], proof, root) or n == 1
        assert not verify_inclusion(i, n, leaves[i], [*proof, root], root)
        if proof:
            assert not verify_inclusion(i, n, leaves[i], proof[:-1], root)


@pytest.mark.parametrize("n", range(0, 71))
def test_consistency_proofs_for_every_prefix(n: int) -> None:
    d = data_of(n)
    leaves = [leaf_hash(x) for x in d]
    new_root = ref_mth(d)
    for m in range(n + 1):
        proof = consistency_proof(m, leaves)
        assert proof == (ref_proof(m, d) if 0 < m < n else [])
        old_root = ref_mth(d[:m])
        assert verify_consistency(m, n, old_root, new_root, proof)
        if not 0 < m < n:
            continue
        # wrong sizes: every pair whose proof has another length fails (a pair of the same
        # length may share the proof's shape: sizes are bound by the signed checkpoints)
        for m2 in range(n + 2):
            if m2 != m and not (0 < m2 < n and len(ref_proof(m2, d)) == len(proof)):
                assert not verify_consistency(m2, n, old_root, new_root, proof)
        for n2 in range(m, n + 3):
            if n2 != n and not (m < n2 and len(ref_proof(m, data_of(n2))) == len(proof)):
                assert not verify_consistency(m, n2, old_root, new_root, proof)
        assert not verify_consistency(m, n * 2, old_root, new_root, proof)
        assert not verify_consistency(m, n, new_root, old_root, proof)
        assert not verify_consistency(m, n, old_root, new_root, [])
        assert not verify_consistency(m, n, old_root, new_root, proof[:-1])
        assert not verify_consistency(m, n, old_root, new_root, [*proof, proof[-1]])
        assert not verify_consistency(m, n, old_root, new_root, [EMPTY_ROOT, *proof])


@pytest.mark.parametrize("n", range(1, 18))
def test_every_single_bit_flip_fails(n: int) -> None:
    d = data_of(n, salt=7)
    leaves = [leaf_hash(x) for x in d]
    root = ref_mth(d)
    for i in range(n):
        for bad in flips(inclusion_proof(i, leaves)):
            assert not verify_inclusion(i, n, leaves[i], bad, root)
    for m in range(1, n):
        old_root = ref_mth(d[:m])
        for bad in flips(consistency_proof(m, leaves)):
            assert not verify_consistency(m, n, old_root, new_root=root, proof=bad)


# ---- random larger trees ----


@settings(max_examples=30, deadline=None)
@given(st.integers(71, 2000), st.data())
def test_random_large_trees(n: int, data: st.DataObject) -> None:
    d = data_of(n, salt=n)
    leaves = [leaf_hash(x) for x in d]
    root = ref_mth(d)
    assert root_of(leaves) == root
    i = data.draw(st.integers(0, n - 1), label="index")
    proof = inclusion_proof(i, leaves)
    assert proof == ref_path(i, d)
    assert verify_inclusion(i, n, leaves[i], proof, root)
    j = data.draw(st.integers(0, len(proof) - 1), label="hash")
    bit = data.draw(st.integers(0, 255), label="bit")
    bad = list(proof)
    bad[j] = (int.from_bytes(bad[j], "big") ^ (1 << bit)).to_bytes(32, "big")
    assert not verify_inclusion(i, n, leaves[i], bad, root)
    assert not verify_inclusion(i, n * 2, leaves[i], proof, root)
    m = data.draw(st.integers(1, n - 1), label="old size")
    cproof = consistency_proof(m, leaves)
    assert cproof == ref_proof(m, d)
    old_root = ref_mth(d[:m])
    assert verify_consistency(m, n, old_root, root, cproof)
    j = data.draw(st.integers(0, len(cproof) - 1), label="consistency hash")
    bad = list(cproof)
    bad[j] = (int.from_bytes(bad[j], "big") ^ (1 << bit)).to_bytes(32, "big")
    assert not verify_consistency(m, n, old_root, root, bad)
    assert not verify_consistency(m, n * 2, old_root, root, cproof)
    assert not verify_consistency(m, n, root, old_root, cproof)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.binary(max_size=40), max_size=200), st.integers(0, 200))
def test_compact_range_of_any_leaves(data: list[bytes], cut: int) -> None:
    leaves = [leaf_hash(x) for x in data]
    head = CompactRange()
    for h in leaves[: min(cut, len(leaves))]:
        head.append(h)
    resumed = CompactRange.restore(*head.state())
    for h in leaves[min(cut, len(leaves)) :]:
        resumed.append(h)
    assert resumed.root() == ref_mth(data)


def test_a_large_tree_is_quick() -> None:
    """200,000 leaves: each proof hashes every interior node at most once (linear)."""
    n = 200_000
    leaves = [leaf_hash(i.to_bytes(4, "big")) for i in range(n)]
    started = time.perf_counter()
    root = root_of(leaves)
    proof = inclusion_proof(123_457, leaves)
    cproof = consistency_proof(99_999, leaves)
    old_root = root_of(leaves[:99_999])
    elapsed = time.perf_counter() - started
    assert verify_inclusion(123_457, n, leaves[123_457], proof, root)
    assert verify_consistency(99_999, n, old_root, root, cproof)
    assert elapsed < 20


# ---- hostile input: False, never an exception ----

GOOD = b"\x11" * 32

HOSTILE_INCLUSION: list[tuple[object, ...]] = [
    (0, 0, GOOD, [], GOOD),
    (-1, 4, GOOD, [GOOD, GOOD], GOOD),
    (4, 4, GOOD, [GOOD, GOOD], GOOD),
    (0, -4, GOOD, [], GOOD),
    (True, 4, GOOD, [GOOD, GOOD], GOOD),
    (0.0, 1, GOOD, [], GOOD),
    ("0", 1, GOOD, [], GOOD),
    (0, 1, GOOD[:31], [], GOOD),
    (0, 1, GOOD, [], GOOD + b"\x00"),
    (0, 2, GOOD, [GOOD[:31]], GOOD),
    (0, 2, GOOD, [b""], GOOD),
    (0, 2, GOOD, [None], GOOD),
    (0, 2, GOOD, None, GOOD),
    (0, 2, GOOD, "x" * 32, GOOD),
    (0, 2, None, [GOOD], GOOD),
    (0, 2**70, GOOD, [GOOD] * 3, GOOD),
    (0, 1, GOOD, [GOOD] * 100_000, GOOD),
]


@pytest.mark.parametrize("args", HOSTILE_INCLUSION)
def test_hostile_inclusion_is_false(args: tuple[object, ...]) -> None:
    assert verify_inclusion(*args) is False  # type: ignore[arg-type]


HOSTILE_CONSISTENCY: list[tuple[object, ...]] = [
    (2, 1, GOOD, GOOD, []),
    (-1, 1, GOOD, GOOD, []),
    (0, 5, GOOD, GOOD, []),  # an empty tree's root is SHA-256("")
    (0, 5, EMPTY_ROOT, GOOD, [GOOD]),
    (3, 3, GOOD, GOOD, [GOOD]),
    (3, 3, GOOD, b"\x22" * 32, []),
    (1, 2, GOOD, GOOD, []),
    (1, 2, GOOD, GOOD, [GOOD[:5]]),
    (1, 2, GOOD, GOOD, None),
    (1, 2, None, GOOD, [GOOD]),
    (1, 2, GOOD, "x", [GOOD]),
    (False, 2, EMPTY_ROOT, GOOD, []),
    (1.0, 2, GOOD, GOOD, [GOOD]),
    (3, 2**80, GOOD, GOOD, [GOOD] * 5),
    (3, 7, GOOD, GOOD, [GOOD] * 10_000),
]


@pytest.mark.parametrize("args", HOSTILE_CONSISTENCY)
def test_hostile_consistency_is_false(args: tuple[object, ...]) -> None:
    assert verify_consistency(*args) is False  # type: ignore[arg-type]


def test_the_empty_tree_and_equal_sizes() -> None:
    assert verify_consistency(0, 0, EMPTY_ROOT, EMPTY_ROOT, [])
    assert verify_consistency(0, 9, EMPTY_ROOT, GOOD, [])
    assert verify_consistency(4, 4, GOOD, GOOD, ())


def test_restore_refuses_what_cannot_be_a_compact_range() -> None:
    with pytest.raises(MerkleError, match="holds 2 hashes, got 1"):
        CompactRange.restore(5, [GOOD])
    with pytest.raises(MerkleError, match="holds 0 hashes"):
        CompactRange.restore(0, [GOOD])
    with pytest.raises(MerkleError, match="32-byte"):
        CompactRange.restore(1, [GOOD[:31]])
    with pytest.raises(MerkleError, match="non-negative"):
        CompactRange.restore(-1, [])
    assert CompactRange.restore(0, []).root() == EMPTY_ROOT


def test_proofs_of_what_is_not_in_the_tree_are_refused() -> None:
    leaves = [GOOD] * 5
    with pytest.raises(MerkleError):
        inclusion_proof(5, leaves)
    with pytest.raises(MerkleError):
        inclusion_proof(-1, leaves)
    with pytest.raises(MerkleError):
        consistency_proof(6, leaves)
    assert consistency_proof(0, leaves) == [] == consistency_proof(5, leaves)
