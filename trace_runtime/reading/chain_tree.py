"""Each robot's Merkle tree over its seals (profile 1.2, schemas/PROFILE.md §6), read from a log.

The leaves are the robot's seals in chain order across all its segments from its genesis, one
leaf per seal, ``merkle.leaf_hash`` of the seal's message data as stored (a dropped cycle has
no seal, so no leaf). A 1.2 checkpoint states the tree through its head seal: ``tree_size``,
``root`` and ``range`` (the compact range a restarted logger or a verifier continues from).

This module reads trees out of files: the leaves of one robot's chain (``robot_leaves``, for
witnesses and proof bundles), a checkpoint's tree as a ``CompactRange``
(``checkpoint_range``), and the tree through a given seal in a log root, for a logger that
resumes a chain (``tree_through``). It never writes and never raises on damage: a tree that
cannot be read is None.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import orjson

from trace_runtime.chain import digest
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.errors import ChainTreeError, MerkleError, RecordError, TraceError
from trace_runtime.reading.copies import best_copy_first
from trace_runtime.reading.logset import Log, open_segments
from trace_runtime.reading.reader import Segment
from trace_runtime.reading.segment_files import robot_segment_files
from trace_runtime.records import GENESIS, TOPIC_CHECKPOINT, TOPIC_SEAL, Checkpoint
from trace_runtime.tlog.checkpoints import decode_checkpoint
from trace_runtime.tlog.merkle import (
    CompactRange,
    consistency_path,
    leaf_hash,
    node_hash,
    root_of,
)

__all__ = [
    "ProvedCycle",
    "SealLeaf",
    "checkpoint_range",
    "consistency_proof_from",
    "has_tree",
    "iter_seal_data",
    "prove_pass",
    "robot_leaves",
    "robot_seal_leaves",
    "segment_seal_leaves",
    "tree_fields",
    "tree_through",
]


@dataclass(frozen=True, slots=True)
class SealLeaf:
    """One leaf of a robot's tree: the seal's cycle and time, its leaf hash, the seal's
    digest (what the next seal names as ``prev``) and the segment number it was read in."""

    cycle: int
    t_ns: int
    leaf: bytes
    digest: str
    prev: str
    """The digest the seal names as the one before it ("" when it names none)."""
    segment: int


def segment_seal_leaves(segment: Segment, start_ns: int | None = None) -> Iterator[SealLeaf]:
    """The leaves of one segment's seals in reading order (chain order in an intact file),
    from ``start_ns`` on when given. Any tier: warm and cold keep every seal's bytes."""
    number = segment.session.segment
    for cycle in segment.iter_cycles(start_ns=start_ns):
        data = cycle.payloads.get(TOPIC_SEAL)
        if data is not None:
            yield SealLeaf(
                cycle.cycle, cycle.t_ns, leaf_hash(data), digest(data), _prev_of(data), number
            )


def _prev_of(data: bytes) -> str:
    try:
        prev = orjson.loads(data).get("prev")
    except (orjson.JSONDecodeError, AttributeError):
        return ""
    return prev if isinstance(prev, str) else ""


def robot_seal_leaves(log: Log, robot: str) -> list[SealLeaf]:
    """Every leaf of ``robot``'s tree the log holds, in chain order, each segment read in the
    copy every reader reads (``copies.preferred_copies``).

    ``ChainTreeError`` when the log does not hold the chain from its genesis (its first
    segment is not number 0 starting at ``GENESIS``) or a segment number is missing: the
    leaf indices would not be the tree's. Whether the seals themselves verify is ``verify``'s
    question; this reads them as stored.
    """
    leaves: list[SealLeaf] = []
    for segment in _genesis_chain(log, robot):
        leaves.extend(segment_seal_leaves(segment))
    return leaves


@dataclass(slots=True)
class ProvedCycle:
    """What a proof of one cycle needs from one pass over the robot's chain: every leaf hash
    (32 bytes each, nothing else kept: a 24 h log's tree is 28 MB), the cycle itself and its
    leaf index (None when the chain holds no seal of it)."""

    leaves: list[bytes]
    cycle: Cycle | None = None
    index: int | None = None


def prove_pass(log: Log, robot: str, number: int) -> ProvedCycle:
    """``robot_leaves`` and the sealed cycle ``number`` with its leaf index, in one read."""
    out = ProvedCycle([])
    leaves = out.leaves
    for segment in _genesis_chain(log, robot):
        for cycle in segment.iter_cycles():
            data = cycle.payloads.get(TOPIC_SEAL)
            if data is None:
                continue
            if cycle.cycle == number and out.cycle is None:
                out.cycle, out.index = cycle, len(leaves)
            leaves.append(leaf_hash(data))
    return out


def iter_seal_data(log: Log, robot: str) -> Iterator[bytes]:
    """The message data of ``robot``'s seals in chain order from its genesis: the entries of
    its tree, leaf ``i`` being ``merkle.leaf_hash`` of the ``i``-th (as ``prove_pass`` reads
    them). ``ChainTreeError`` as ``robot_seal_leaves``."""
    for segment in _genesis_chain(log, robot):
        for cycle in segment.iter_cycles():
            data = cycle.payloads.get(TOPIC_SEAL)
            if data is not None:
                yield data


def _genesis_chain(log: Log, robot: str) -> Iterator[Segment]:
    """``robot``'s segments in chain order, from its genesis; ``ChainTreeError`` when the
    chain does not start at genesis here or a segment number is missing."""
    segments = log.segments_of(robot)
    if not segments:
        raise ChainTreeError(str(log.root), f"the log holds no segment of robot {robot}")
    first = segments[0].session
    if first.segment != 0 or first.prev_seal != GENESIS:
        raise ChainTreeError(
            str(segments[0].path),
            f"robot {robot}'s chain starts at segment {first.segment} here, not at its genesis: "
            "the leaf indices of its tree are not known",
        )
    expected = 0
    for segment in segments:
        number = segment.session.segment
        if number != expected:
            raise ChainTreeError(
                str(segment.path),
                f"segment(s) {expected}..{number - 1} of robot {robot} are missing",
            )
        expected = number + 1
        yield segment


def robot_leaves(log: Log, robot: str) -> list[bytes]:
    """The leaf hashes of ``robot``'s tree in order, read from the files (see
    ``robot_seal_leaves``): ``merkle.root_of(robot_leaves(log, r)[:n])`` is the root a
    checkpoint with ``tree_size == n`` states."""
    return [s.leaf for s in robot_seal_leaves(log, robot)]


def has_tree(checkpoint: Checkpoint) -> bool:
    """Whether a checkpoint states a tree (profile 1.2): its size, root and range."""
    c = checkpoint
    return c.tree_size is not None and c.root is not None and c.range is not None


def checkpoint_range(checkpoint: Checkpoint) -> CompactRange | None:
    """The compact range a 1.2 checkpoint states, when it is one and agrees with the
    checkpoint's own ``tree_size`` and ``root``; None otherwise (1.0/1.1, or inconsistent)."""
    c = checkpoint
    if c.tree_size is None or c.root is None or c.range is None:
        return None
    try:
        restored = CompactRange.restore(c.tree_size, [bytes.fromhex(h) for h in c.range])
    except (ValueError, MerkleError):
        return None
    return restored if restored.root().hex() == c.root else None


def tree_fields(compact: CompactRange) -> tuple[int, str, list[str]]:
    """A tree as a checkpoint states it: ``(tree_size, root hex, range as hex)``."""
    return compact.size, compact.root().hex(), [h.hex() for h in compact.hashes]


def consistency_proof_from(old: CompactRange, new_leaves: Sequence[bytes]) -> list[bytes]:
    """The RFC 9162 consistency proof from the tree of ``old.size`` leaves to the tree with
    ``new_leaves`` appended, from what a writer keeps: the old tree's compact range and the
    leaf hashes since (every hash of the proof below ``old.size`` is a subtree root of that
    range, every one above it is made of the new leaves). Equal to
    ``merkle.consistency_proof(old.size, all_leaves)``; empty when ``old.size`` is 0 or
    nothing was appended."""
    m = old.size
    n = m + len(new_leaves)
    if m in (0, n):
        return []
    nodes: dict[tuple[int, int], bytes] = {}
    lo = 0
    for h in old.hashes:  # largest first: the binary digits of m, high to low
        width = 1 << ((m - lo).bit_length() - 1)
        nodes[(lo, lo + width)] = h
        lo += width

    def subtree(a: int, b: int) -> bytes:
        if a >= m:
            return root_of(new_leaves[a - m : b - m])
        found = nodes.get((a, b))
        if found is not None:
            return found
        half = 1 << ((b - a - 1).bit_length() - 1)  # not reached for a proof: kept exact
        return node_hash(subtree(a, a + half), subtree(a + half, b))

    return consistency_path(m, n, subtree)


# --- the tree through a seal, for a logger that resumes a chain -------------------------------


def tree_through(root: Path, robot_id: str, head: str) -> CompactRange | None:
    """The robot's tree through the seal whose digest is ``head``, read from a log root.

    From the newest 1.2 checkpoint at or before that seal (its ``range``) plus the seals after
    it, in the segment it was written in and the later ones; without any, every seal from the
    robot's oldest segment in the root (its genesis, unless retention removed early segments
    before they had a tree). The links are followed: every seal appended must be the one the
    chain continues with. None when ``head`` is not found or the chain cannot be followed to
    it (damage); the logger then writes checkpoints without a tree.
    """
    numbered = robot_segment_files(root, robot_id)
    visited: list[list[SealLeaf]] = []  # newest segment first
    found = False
    for number in sorted(numbered, reverse=True):
        segment = _best_copy(numbered[number])
        if segment is None:
            continue
        if not found:
            if not _holds_digest(segment, head):
                continue
            found = True
        start = _newest_tree_checkpoint(segment, head if not visited else None)
        if start is not None:
            checkpoint, compact = start
            leaves = _after(list(segment_seal_leaves(segment, checkpoint.t_ns)), checkpoint.head)
            if leaves is None:
                return None
            return _extend(compact, checkpoint.head, [leaves, *reversed(visited)], head)
        visited.append(list(segment_seal_leaves(segment)))
    if not found:
        return None
    return _extend(CompactRange(), None, list(reversed(visited)), head)


def _best_copy(files: list[Path]) -> Segment | None:
    segments, _problems = open_segments(sorted(files))
    if not segments:
        return None
    return best_copy_first(segments)[0]


def _holds_digest(segment: Segment, head: str) -> bool:
    """Whether the seal ``head`` names is in the segment (read from its end)."""
    try:
        for cycle in segment.iter_cycles(reverse=True):
            data = cycle.payloads.get(TOPIC_SEAL)
            if data is not None and digest(data) == head:
                return True
    except TraceError:
        return False
    return False


def _newest_tree_checkpoint(
    segment: Segment, head: str | None
) -> tuple[Checkpoint, CompactRange] | None:
    """The segment's newest 1.2 checkpoint whose range agrees with itself (with ``head``:
    only one written at or before that seal, i.e. the newest before a crash cut the file)."""
    seen_head = head is None
    try:
        for message in segment.iter_messages(reverse=True):
            if message.topic == TOPIC_SEAL and not seen_head:
                seen_head = digest(message.data) == head
                continue
            if message.topic != TOPIC_CHECKPOINT:
                continue
            try:
                checkpoint = decode_checkpoint(message.data)
            except RecordError:
                continue
            if not seen_head and checkpoint.head != head:
                continue  # written after the seal the chain goes on from
            compact = checkpoint_range(checkpoint)
            if compact is not None:
                return checkpoint, compact
    except TraceError:
        return None
    return None


def _after(leaves: list[SealLeaf], head: str) -> list[SealLeaf] | None:
    """The leaves after the seal ``head``, or None if it is not among them."""
    for i, leaf in enumerate(leaves):
        if leaf.digest == head:
            return leaves[i + 1 :]
    return None


def _extend(
    compact: CompactRange, start: str | None, parts: Sequence[list[SealLeaf]], head: str
) -> CompactRange | None:
    """Append the leaves of ``parts`` (oldest first) up to and including the seal ``head``,
    each seal naming the one before it (the first, ``start``, when given); None when a link
    breaks or ``head`` is not reached."""
    if start == head:
        return compact  # the checkpoint names the seal the chain goes on from
    previous = start
    for part in parts:
        for leaf in part:
            if previous is not None and leaf.prev != previous:
                return None
            compact.append(leaf.leaf)
            if leaf.digest == head:
                return compact
            previous = leaf.digest
    return None
