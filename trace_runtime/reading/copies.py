"""Which copy of a segment is read when a root holds several (a compaction under way or
interrupted, a copy made by hand): the one owner of copy choice. Lossless before lossy,
finished before recovered, the lower tier first; a copy proven to be another cut short
always gives way to the longer; two different recordings of one position are a fork."""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Sequence
from pathlib import Path

from trace_runtime.encoding.cycles import Cycle
from trace_runtime.errors import (
    LogReadError,
)
from trace_runtime.reading.reader import Segment
from trace_runtime.records import TOPIC_SEAL
from trace_runtime.session import TIER_METADATA, TIERS

fork_log = logging.getLogger("trace_runtime.forks")
"""Where a fork (two recordings at one chain position) is warned of; a caller that refuses
forks itself (the fleet index) silences it."""


def copy_rank(segment: Segment) -> tuple[int, int, int]:
    """How much of the robot's record a copy of a segment holds; lower is read first.

    A hot segment is the original. A cold copy is a lossless re-encoding of its source, so
    a cold copy of a hot segment holds everything; a warm copy (and a cold copy of a warm
    one) holds summaries. Among lossless (or among lossy) copies a finished file comes
    before a recovered one (a crash or an interrupted copy may have cut it), then the less
    re-encoded copy wins.
    """
    tier = segment.session.tier
    lossy = tier == "warm" or (
        tier == "cold" and segment.metadata.get(TIER_METADATA, {}).get("lossy") == "true"
    )
    return (
        1 if lossy else 0,
        0 if segment.finished else 1,
        TIERS.index(tier) if tier in TIERS else 9,
    )


def preferred_copies(segments: Sequence[Segment]) -> tuple[list[Segment], list[Segment]]:
    """One copy of each segment of a robot's chain: ``(read, shadowed)``.

    While a compaction runs (or after one was interrupted) a segment sits in two tiers of a
    root; a segment copied by hand may sit beside its original, whole or cut short. Exactly
    one copy of each chain position is read, so no decision is counted twice: the first by
    ``copy_rank`` (lossless, then finished, then the lower tier), and a copy proven to be
    another cut short (``cut_short_copy``) always gives way to the longer. The others are
    listed as shadowed (``verify`` checks each).
    Only copies that opened are compared, so a damaged copy never shadows a readable one.
    Two files of one tier at one position that are neither the same bytes nor one cut from
    the other are two recordings (a fork): one is read, a warning names both, and
    ``verify`` reports the fork.
    """
    by_position: dict[tuple[str, int, int, str], list[Segment]] = {}
    for segment in segments:
        session = segment.session
        key = (session.robot_id, session.segment, session.first_cycle, session.prev_seal)
        by_position.setdefault(key, []).append(segment)
    read: list[Segment] = []
    shadowed: list[Segment] = []
    for copies in by_position.values():
        best, *others = best_copy_first(copies)
        read.append(best)
        shadowed.extend(others)
    return read, shadowed


def best_copy_first(copies: list[Segment]) -> list[Segment]:
    """Copies of one chain position, the one every reader reads first: the first by
    ``copy_rank``, unless it is proven to be another copy cut short (``cut_short_copy``)."""
    if len(copies) == 1:
        return copies
    ranked = sorted(copies, key=copy_rank)
    best = ranked[0]
    for other in ranked[1:]:
        if cut_short_copy(best, other):
            best = other
    others = [c for c in ranked if c is not best]
    for other in others:
        if (
            other.session.tier == best.session.tier
            and not _same_bytes(other.path, best.path)
            and not cut_short_copy(other, best)
        ):
            fork_log.warning(
                "%s and %s are two different recordings of segment %d of robot %s (a fork; "
                "trace-audit verify reports it): reading %s",
                best.path,
                other.path,
                best.session.segment,
                best.session.robot_id,
                best.path.name,
            )
    return [best, *others]


def cut_short_copy(copy: Segment, of: Segment) -> bool:
    """Whether ``copy`` is ``of`` cut short (a crash, an interrupted copy), holding nothing
    that ``of`` does not: ``copy`` is unfinished, its last seal is, byte for byte, ``of``'s
    seal of that cycle, and ``of`` is finished or goes on past it. A seal commits to its
    cycle and, through the hash chain, to every cycle before it in the segment."""
    if copy.finished:
        return False
    try:
        last = _last_sealed(copy)
        same = of.cycle_at(last.t_ns) if last is not None else None
        if (
            last is None
            or same is None
            or same.cycle != last.cycle
            or same.payloads.get(TOPIC_SEAL) != last.payloads[TOPIC_SEAL]
        ):
            return False
        if of.finished:
            return True
        end = _last_sealed(of)
    except LogReadError:
        return False
    return end is not None and end.cycle > last.cycle


def _last_sealed(segment: Segment) -> Cycle | None:
    return next((c for c in segment.iter_cycles(reverse=True) if c.sealed), None)


def _same_bytes(a: Path, b: Path) -> bool:
    """Whether two files hold the same bytes (sizes first, then their SHA-256)."""
    try:
        if a.stat().st_size != b.stat().st_size:
            return False
        with open(a, "rb") as fa, open(b, "rb") as fb:
            return (
                hashlib.file_digest(fa, "sha256").digest()
                == hashlib.file_digest(fb, "sha256").digest()
            )
    except OSError:
        return False
