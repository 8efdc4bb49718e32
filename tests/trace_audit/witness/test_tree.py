"""``LevelTree`` gives exactly ``trace_runtime.tlog.merkle``'s roots and proofs (which are pinned
to Go's tlog), for every size and index up to 70 leaves and random ones beyond."""

from __future__ import annotations

import hashlib
import random

import pytest

from trace_audit.witness.tree import LevelTree
from trace_runtime.errors import MerkleError
from trace_runtime.tlog.merkle import consistency_proof, inclusion_proof, root_of

LEAVES = [hashlib.sha256(b"%d" % i).digest() for i in range(1100)]


def test_every_small_tree() -> None:
    tree = LevelTree(LEAVES[:70])
    for size in range(71):
        assert tree.root(size) == root_of(LEAVES[:size])
        for old in range(size + 1):
            assert tree.consistency_proof(old, size) == consistency_proof(old, LEAVES[:size])
        for index in range(size):
            assert tree.inclusion_proof(index, size) == inclusion_proof(index, LEAVES[:size])


def test_random_larger_trees() -> None:
    rng = random.Random(7)
    tree = LevelTree(LEAVES)
    for _ in range(200):
        size = rng.randint(1, len(LEAVES))
        old, index = rng.randint(0, size), rng.randrange(size)
        assert tree.root(size) == root_of(LEAVES[:size])
        assert tree.consistency_proof(old, size) == consistency_proof(old, LEAVES[:size])
        assert tree.inclusion_proof(index, size) == inclusion_proof(index, LEAVES[:size])


def test_out_of_range() -> None:
    tree = LevelTree(LEAVES[:5])
    with pytest.raises(MerkleError):
        tree.root(6)
    with pytest.raises(MerkleError):
        tree.inclusion_proof(5, 5)
    with pytest.raises(MerkleError):
        tree.consistency_proof(3, 6)
    with pytest.raises(MerkleError):
        tree.consistency_proof(4, 3)
