"""The Merkle tree's cost per robot cycle, against the target of 3 us a cycle.

    .venv/bin/python bench/bench_merkle.py [--quick]

What a logger pays per cycle to keep the tree of its seals (``trace_runtime.tlog.merkle``):
``leaf_hash`` of one seal (~300 bytes, the size of a cycle's seal record) and
``CompactRange.append`` of that leaf hash (about one node hash amortised). Each is timed over
100,000 leaves, the median of several runs, in microseconds per leaf; also, for scale, one
bare SHA-256 of the seal and of 65 bytes (one node), and ``root()`` of the range at the end
(paid once per checkpoint, not per cycle).
"""

from __future__ import annotations

import argparse
import hashlib
import os
import statistics
import time
from collections.abc import Callable

from trace_runtime.tlog.merkle import CompactRange, leaf_hash

TARGET_US = 3.0
SEAL_BYTES = 300


def per_item_us(work: Callable[[], object], items: int, runs: int) -> float:
    """The median over ``runs`` of one timed call of ``work``, in us per item."""
    times = []
    for _ in range(runs):
        started = time.perf_counter()
        work()
        times.append((time.perf_counter() - started) / items * 1e6)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer leaves and runs")
    args = parser.parse_args()
    n, runs = (20_000, 5) if args.quick else (100_000, 9)
    seals = [os.urandom(SEAL_BYTES) for _ in range(n)]
    leaves = [leaf_hash(s) for s in seals]
    node = os.urandom(65)
    sha256 = hashlib.sha256

    def hash_leaves() -> None:
        for s in seals:
            leaf_hash(s)

    def append_leaves() -> None:
        compact = CompactRange()
        for h in leaves:
            compact.append(h)

    def both() -> None:
        compact = CompactRange()
        for s in seals:
            compact.append(leaf_hash(s))

    def bare_seal() -> None:
        for s in seals:
            sha256(s).digest()

    def bare_node() -> None:
        for _ in range(n):
            sha256(node).digest()

    def loop_only() -> None:
        for _ in seals:
            pass

    compact = CompactRange()
    for h in leaves:
        compact.append(h)
    roots = 1000

    def root_many() -> None:
        for _ in range(roots):
            compact.root()

    print(f"{n} leaves ({SEAL_BYTES}-byte seals), median of {runs} runs, us/leaf")
    cycle = per_item_us(both, n, runs)
    rows = [
        ("leaf_hash(seal)", per_item_us(hash_leaves, n, runs)),
        ("CompactRange.append(leaf hash)", per_item_us(append_leaves, n, runs)),
        ("per cycle: append(leaf_hash(seal))", cycle),
    ]
    for name, us in rows:
        print(f"  {name:40s} {us:7.3f}")
    print(f"  target {TARGET_US:.1f} us a cycle: {'met' if cycle <= TARGET_US else 'MISSED'}")
    print("for scale:")
    for name, us in [
        ("SHA-256 of the seal alone", per_item_us(bare_seal, n, runs)),
        ("SHA-256 of 65 bytes (one node)", per_item_us(bare_node, n, runs)),
        ("the Python loop alone", per_item_us(loop_only, n, runs)),
    ]:
        print(f"  {name:40s} {us:7.3f}")
    root_us = per_item_us(root_many, roots, runs)
    name = f"root() at {n} leaves ({len(compact.hashes)} subtrees), per call"
    print(f"  {name:40s} {root_us:7.3f}")


if __name__ == "__main__":
    main()
