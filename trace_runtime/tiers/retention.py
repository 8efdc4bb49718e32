"""Retention of the cold tier: old cold segments that ``verify`` finds clean, whose successor
continues their chain, are deleted, each deletion recorded in ``retention.jsonl`` first;
every other one is held as evidence.

Retention takes only the oldest part of a robot's chain: a segment is deleted only when every
segment before it is gone or deleted in the same run, so what remains always starts at one
segment and runs on without a hole (``verify`` notes a ``chain_start``, never a
``missing_segment``)."""

from __future__ import annotations

import time
from pathlib import Path

import orjson

from trace_runtime.boundary import append_line, remove_own_file
from trace_runtime.errors import TraceError
from trace_runtime.reading.logset import Log, open_segments
from trace_runtime.reading.reader import Segment
from trace_runtime.tiers.catalog import file_digest, segment_files
from trace_runtime.tiers.report import RetentionResult, rel_path
from trace_runtime.tlog.keys import PublicKey
from trace_runtime.verification import SegmentSummary, VerifyReport, verify

RETENTION_LOG = "retention.jsonl"


def apply_retention(
    root: Path, cutoff_ns: int, robot: str | None, dry_run: bool, key: PublicKey | None
) -> list[RetentionResult]:
    """Delete old cold segments that ``verify`` finds clean; hold every other one."""
    out: list[RetentionResult] = []
    segments, problems = open_segments(segment_files(root))
    for problem in problems:
        if problem.path.parent.name == "cold":
            rel = rel_path(root, problem.path)
            out.append(RetentionResult(rel, 0, "kept", f"held: unreadable ({problem.reason})"))
    candidates = [
        s
        for s in segments
        if s.session.tier == "cold"
        and s.path.parent.name == "cold"
        and (robot is None or s.session.robot_id == robot)
        and s.info.end_ns < cutoff_ns
    ]
    for robot_id in sorted({s.session.robot_id for s in candidates}):
        mine = [s for s in candidates if s.session.robot_id == robot_id]
        chain = [s for s in segments if s.session.robot_id == robot_id]
        out += _retire(root, mine, chain, dry_run, key)
    return out


def _retire(
    root: Path,
    candidates: list[Segment],
    chain: list[Segment],
    dry_run: bool,
    key: PublicKey | None,
) -> list[RetentionResult]:
    """One robot's old cold segments: verify its chain up to the newest of them, delete each
    one that verify finds nothing in, whose successor continues from its last seal."""
    last = max(s.session.segment for s in candidates)
    report = verify(Log([s for s in chain if s.session.segment <= last], root), key=key)
    summaries = {Path(s.path): s for s in report.segments}
    named = {f.segment for f in report.findings}
    out: list[RetentionResult] = []
    taken = {s.path for s in candidates}  # what this run may still delete
    for segment in sorted(candidates, key=lambda s: s.session.segment):
        rel, end = rel_path(root, segment.path), segment.info.end_ns
        why = _retention_hold(segment, summaries[segment.path], named, chain, report)
        if not why:
            why = _hole_it_would_leave(segment, chain, taken)
        if why:
            taken.discard(segment.path)
            out.append(RetentionResult(rel, end, "kept", why))
            continue
        if dry_run:
            out.append(RetentionResult(rel, end, "would delete"))
            continue
        out.append(_delete(root, segment, summaries[segment.path].last_seal))
    return out


def _hole_it_would_leave(segment: Segment, chain: list[Segment], taken: set[Path]) -> str:
    """Why deleting ``segment`` would leave a hole in the chain ("" when it would not): an
    older segment of the robot stays (held, in another tier, or not old enough)."""
    number = segment.session.segment
    kept = sorted(
        s.session.segment for s in chain if s.session.segment < number and s.path not in taken
    )
    if kept:
        return f"held: segment {kept[0]} before it is kept (deleting this would leave a hole)"
    return ""


def _delete(root: Path, segment: Segment, last_seal: str | None) -> RetentionResult:
    """Record ``segment``'s deletion in the journal (fsynced), then delete it."""
    rel, end = rel_path(root, segment.path), segment.info.end_ns
    try:
        _record_retired(root, segment.path, segment, last_seal)
    except (TraceError, OSError) as err:
        return RetentionResult(rel, end, "kept", f"cannot record the deletion: {err}")
    why_not = remove_own_file(segment.path)
    if why_not:
        return RetentionResult(rel, end, "kept", f"not deleted: {why_not}")
    return RetentionResult(rel, end, "deleted")


def _retention_hold(
    segment: Segment,
    summary: SegmentSummary,
    named: set[str],
    chain: list[Segment],
    report: VerifyReport,
) -> str:
    """Why retention must keep ``segment`` ("" when nothing stops it)."""
    name = f"cold/{segment.path.name}"
    if not summary.ok or name in named:
        first = next((f for f in report.findings if f.segment == name), None)
        return "held: findings" + (f" ({first.kind}: {first.message})" if first else "")
    if summary.copy or any(
        s.path != segment.path and s.path.name == segment.path.name for s in chain
    ):
        return "held: the segment is in two tiers"
    after = [s for s in chain if s.session.segment == segment.session.segment + 1]
    tail = summary.last_seal or segment.session.prev_seal  # an empty segment passes it on
    if any(s.session.prev_seal != tail for s in after):
        return "held: the next segment does not continue its chain"
    return ""


def _record_retired(root: Path, path: Path, segment: Segment, last_seal: str | None) -> None:
    line = {
        "path": rel_path(root, path),
        "robot": segment.session.robot_id,
        "segment": segment.session.segment,
        "start_ns": segment.info.start_ns,
        "end_ns": segment.info.end_ns,
        "prev_seal": segment.session.prev_seal,
        "last_seal": last_seal,
        "sha256": file_digest(path),
        "deleted_at_ns": time.time_ns(),
    }
    append_line(root / RETENTION_LOG, orjson.dumps(line) + b"\n")
