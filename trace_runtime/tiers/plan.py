"""Which segments of a log root a compaction moves: the segments found, the reference time
their age is measured against, and why each one that stays is left."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import orjson

from trace_runtime.reading.logset import FileProblem, open_segments
from trace_runtime.reading.reader import Segment
from trace_runtime.records import TOPIC_SEAL
from trace_runtime.tier_formats.cold import INDEX_TOPIC
from trace_runtime.tiers.catalog import segment_files
from trace_runtime.tiers.report import SegmentResult, Status, file_size, rel_path


def robot_order(segment: Segment) -> tuple[str, int]:
    """Sort key: robot, then segment number."""
    return segment.session.robot_id, segment.session.segment


def scan(root: Path) -> tuple[dict[Path, Segment], list[FileProblem]]:
    """Every segment file of the root opened (by path), and the files that could not be."""
    segments, problems = open_segments(segment_files(root))
    return {s.path: s for s in segments}, problems


def in_two_tiers(root: Path) -> set[str]:
    """Names of segment files present in more than one tier (held by ``recover``)."""
    seen: dict[str, int] = {}
    for path in segment_files(root):
        seen[path.name] = seen.get(path.name, 0) + 1
    return {name for name, count in seen.items() if count > 1}


def live_segments(segments: dict[Path, Segment]) -> set[Path]:
    """Each robot's newest hot segment when it is not finished: its logger may be writing it."""
    newest: dict[str, tuple[int, Path, Segment]] = {}
    for path, segment in segments.items():
        if segment.session.tier != "hot":
            continue
        key = segment.session.robot_id
        if key not in newest or segment.session.segment > newest[key][0]:
            newest[key] = (segment.session.segment, path, segment)
    return {path for _, path, segment in newest.values() if not segment.info.finished}


def cycle_estimate(segment: Segment) -> int:
    """The cycles a segment holds, from its summary or index when it can tell (for progress)."""
    if segment.info.finished and TOPIC_SEAL in segment.info.channels:
        return segment.info.channels[TOPIC_SEAL]
    if segment.session.tier == "cold":
        return sum(
            int(orjson.loads(m.data).get("cycles", 0))
            for m in segment.iter_messages()
            if m.topic == INDEX_TOPIC
        )
    period = max(1, segment.session.period_ns)
    return max(1, (segment.info.end_ns - segment.info.start_ns) // period + 1)


def segment_result(
    root: Path, path: Path, segment: Segment, target: Path | None, *, status: Status, detail: str
) -> SegmentResult:
    """The result of one segment before anything was written (no size after yet)."""
    return SegmentResult(
        source=rel_path(root, path),
        target=rel_path(root, target) if target is not None else None,
        robot=segment.session.robot_id,
        segment=segment.session.segment,
        source_tier=segment.session.tier,
        cycles=cycle_estimate(segment),
        bytes_before=segment.info.bytes,
        bytes_after=None,
        status=status,
        detail=detail,
    )


Reference = Literal["newest log time", "wall clock", "given"]


def reference_time(
    segments: dict[Path, Segment], *, now_ns: int | None, wall_clock: bool
) -> tuple[int | None, Reference]:
    """The time a segment's age is measured against, and what it is: ``now_ns`` if given,
    the wall clock if asked, else the newest log time in the root (None: no segments)."""
    if now_ns is not None:
        return now_ns, "given"
    if wall_clock:
        return time.time_ns(), "wall clock"
    return max((s.info.end_ns for s in segments.values()), default=None), "newest log time"


def unreadable_results(root: Path, problems: list[FileProblem]) -> list[SegmentResult]:
    """A skipped result for every segment file that could not be opened."""
    return [
        SegmentResult(
            rel_path(root, problem.path),
            None,
            "",
            -1,
            problem.path.parent.name,
            0,
            file_size(problem.path),
            None,
            "skipped",
            problem.reason,
        )
        for problem in problems
    ]


@dataclass(frozen=True, slots=True)
class Choice:
    """Which segments may move: from these tiers (and robot), last written before ``cutoff_ns``."""

    sources: tuple[str, ...]
    robot: str | None
    cutoff_ns: int | None
    include_unfinished: bool


def plan_moves(
    root: Path, segments: dict[Path, Segment], choice: Choice
) -> tuple[list[tuple[Path, Segment]], list[SegmentResult]]:
    """(the segments to move, in robot and segment order; a skipped result for each segment of
    the chosen tiers and robot that stays, saying why)."""
    held = in_two_tiers(root)
    live = live_segments(segments)
    plan: list[tuple[Path, Segment]] = []
    skipped: list[SegmentResult] = []
    for path, segment in sorted(segments.items(), key=lambda item: robot_order(item[1])):
        session = segment.session
        if session.tier not in choice.sources or choice.robot not in (None, session.robot_id):
            continue
        why = ""
        if path.name in held:
            why = "held: the segment is in two tiers (see the leftovers)"
        elif choice.cutoff_ns is None or segment.info.end_ns > choice.cutoff_ns:
            why = "newer than the cutoff"
        elif path in live and not choice.include_unfinished:
            why = "unfinished newest hot segment: its logger may still be writing it"
        if why:
            skipped.append(segment_result(root, path, segment, None, status="skipped", detail=why))
            continue
        plan.append((path, segment))
    return plan, skipped
