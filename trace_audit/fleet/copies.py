"""Which file holds each chain position of the fleet index (robot, segment number, first
cycle): two copies of one segment among the inputs keep the one every reader reads, a copy
of a position the index already holds from a better file is left out, and two different
logs at one position are refused (``UsageError``), since a position holds one segment's
rows."""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from trace_audit.fleet.task import IndexTask
from trace_runtime.errors import LogReadError, UsageError
from trace_runtime.reading.copies import preferred_copies
from trace_runtime.reading.logset import Log, open_logs
from trace_runtime.reading.reader import Segment, open_segment
from trace_runtime.records import TOPIC_SEAL

__all__ = ["against_manifest", "chain_position", "one_copy_each", "open_refusing_forks"]


def chain_position(segment: Segment) -> str:
    """The index key of a segment's chain position: ``robot/segment/first cycle``."""
    session = segment.session
    return f"{session.robot_id}/{session.segment:06d}/{session.first_cycle}"


def _identity(segment: Segment) -> str:
    """What tells two recordings apart: the bytes of the first seal (its chain link and
    layer digests); two copies of one segment, however truncated, share it."""
    for cycle in segment.iter_cycles():
        sealed = cycle.payloads.get(TOPIC_SEAL)
        if sealed is not None:
            return hashlib.sha256(sealed).hexdigest()
    return f"empty@{segment.info.start_ns}"


def _different_logs(a: str | Path, b: str | Path, key: str) -> UsageError:
    robot, number, cycle = key.split("/")
    return UsageError(
        f"{a} and {b} are two different logs of robot {robot} at segment {int(number)} "
        f"(cycle {cycle}); index them into separate indexes or give the robots distinct ids"
    )


def open_refusing_forks(paths: Sequence[str | Path]) -> Log:
    # The index refuses two recordings at one position itself, naming both (one line):
    # the readers' warning about the same fork would say it twice.
    forks = logging.getLogger("trace_runtime.forks")
    was, forks.disabled = forks.disabled, True
    try:
        return open_logs(paths)
    finally:
        forks.disabled = was


def one_copy_each(log: Log) -> tuple[set[Path], list[str]]:
    """Inputs holding one chain position twice: the same segment in two copies keeps the
    best (the others are named in a note); two different logs are refused (exit 2), since
    one position holds one segment's rows."""
    by_key: dict[str, list[Segment]] = {}
    for segment in [*log.segments, *log.shadowed]:
        by_key.setdefault(chain_position(segment), []).append(segment)
    left_out: set[Path] = set()
    notes: list[str] = []
    for key, copies in by_key.items():
        if len(copies) < 2:
            continue
        first = _identity(copies[0])
        for other in copies[1:]:
            if _identity(other) != first:
                raise _different_logs(copies[0].path, other.path, key)
        best = copies[0]  # the copy every reader reads (copies.preferred_copies)
        for copy in copies:
            if copy is not best:
                left_out.add(copy.path)
                kind = "a recovered (truncated) copy" if not copy.info.finished else "a copy"
                notes.append(f"{copy.path}: {kind} of {best.path}, which is indexed")
    return left_out, notes


def against_manifest(task: IndexTask, entry: dict[str, Any] | None) -> str | None:
    """A position the index already holds from another file that is still there: refused
    when it is another log; a note (and the task dropped) when the indexed copy is the
    better one. None: index the task."""
    if entry is None or entry.get("path") == task.path or not Path(entry["path"]).is_file():
        return None  # new, the same file, or moved (compacted into another tier)
    try:
        held = open_segment(entry["path"])
    except LogReadError:
        return None  # the indexed file is no longer readable: the new copy replaces it
    new = open_segment(task.path)
    if _identity(held) != _identity(new):
        raise _different_logs(entry["path"], task.path, task.key)
    (read,), _ = preferred_copies([held, new])
    if read is held:
        return f"{task.path}: a copy of {entry['path']}, which stays indexed"
    return None
