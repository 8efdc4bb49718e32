"""A log of many segments: the one owner of which files make up a log, which copy of a
segment found in two tiers is read, and each robot's chain across segments.

Every reader of more than one file (``explain``, ``metrics``, ``verify``, compaction,
retention) opens logs here, so they all read the same copy of every segment and agree on
what could not be read (``Log.problems``): one unreadable file in a root is a problem to
report, not a reason to refuse the other segments.
"""

from __future__ import annotations

import bisect
import hashlib
import logging
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from trace_runtime.cycles import Cycle
from trace_runtime.errors import LogReadError, NotTraceLogError, TimeOutOfRangeError, UsageError
from trace_runtime.integrity import SealStatus, verify_cycle
from trace_runtime.mcap_file import DEFAULT_LIMITS, ReadLimits
from trace_runtime.reader import Segment
from trace_runtime.session import TIER_METADATA, TIERS

log = logging.getLogger("trace_runtime")


PARTIAL_MARK = ".partial"
"""File names holding this are writes in progress (compaction), never read as segments."""


@dataclass(frozen=True, slots=True)
class FileProblem:
    """A file of a log that could not be read, and why (one line)."""

    path: Path
    reason: str
    foreign: bool = False
    """The file is MCAP (or something else) that is not a TRACE segment: not damage."""


def copy_rank(segment: Segment) -> tuple[int, int]:
    """How much of the robot's record a copy of a segment holds; lower is read first.

    A hot segment is the original. A cold copy is a lossless re-encoding of its source, so
    a cold copy of a hot segment holds everything; a warm copy (and a cold copy of a warm
    one) holds summaries. Among equals the less re-encoded copy wins.
    """
    tier = segment.session.tier
    lossy = tier == "warm" or (
        tier == "cold" and segment.metadata.get(TIER_METADATA, {}).get("lossy") == "true"
    )
    return (1 if lossy else 0, TIERS.index(tier) if tier in TIERS else 9)


def preferred_copies(segments: Sequence[Segment]) -> tuple[list[Segment], list[Segment]]:
    """One copy of each segment of a robot's chain: ``(read, shadowed)``.

    While a compaction runs (or after one was interrupted) a segment sits in two tiers of a
    root. The copy read is the one holding the most (``copy_rank``); the others are listed
    as shadowed. Only copies that opened are compared, so a damaged copy never shadows a
    readable one. A byte-identical copy (a segment copied by hand into another directory)
    is read once. Two different files of one tier with one chain position are both read
    (``verify`` reports the fork).
    """
    if not any(s.path.parent.name in ("warm", "cold") for s in segments):
        return list(segments), []
    chosen: dict[tuple[str, int, int, str], Segment] = {}
    same_tier: list[Segment] = []
    shadowed: list[Segment] = []
    for segment in segments:
        session = segment.session
        key = (session.robot_id, session.segment, session.first_cycle, session.prev_seal)
        other = chosen.get(key)
        if other is None:
            chosen[key] = segment
        elif other.session.tier == session.tier:
            if _same_bytes(segment.path, other.path):
                shadowed.append(segment)
            else:
                same_tier.append(segment)
        elif copy_rank(segment) < copy_rank(other):
            shadowed.append(other)
            chosen[key] = segment
        else:
            shadowed.append(segment)
    return same_tier + list(chosen.values()), shadowed


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


def find_segment_files(path: Path) -> list[Path]:
    """Segment files of a log: the file itself, or every ``*.mcap`` below a directory
    (writes in progress excluded)."""
    if path.is_dir():
        return sorted(p for p in path.rglob("*.mcap") if p.is_file() and PARTIAL_MARK not in p.name)
    return [path]


class Log:
    """One or more segments read as one log: per robot, in chain order, across tiers."""

    def __init__(
        self,
        segments: Sequence[Segment],
        root: Path,
        problems: Sequence[FileProblem] = (),
    ) -> None:
        self.root = root
        self.problems = list(problems)
        if not segments:
            reason = self.problems[0].reason if len(self.problems) == 1 else None
            raise LogReadError(
                str(self.problems[0].path if reason else root),
                reason or "no readable TRACE segments found",
            )
        kept, self.shadowed = preferred_copies(segments)
        self.segments = sorted(kept, key=lambda s: (s.start_ns, s.path.name))
        self._starts = [s.start_ns for s in self.segments]
        # A segment that holds nothing (a logger opened and closed without a cycle) has no
        # time range; its zeros must not stretch the log's range back to the epoch.
        self._timed = [s for s in self.segments if s.holds_messages] or self.segments

    @property
    def robots(self) -> list[str]:
        """The robots whose segments make up the log, sorted."""
        return sorted({s.session.robot_id for s in self.segments})

    def segments_of(self, robot_id: str) -> list[Segment]:
        """One robot's segments in chain order (segment number, then first cycle)."""
        return sorted(
            (s for s in self.segments if s.session.robot_id == robot_id),
            key=lambda s: (s.session.segment, s.session.first_cycle, s.path.name),
        )

    def iter_chain(self, robot_id: str) -> Iterator[tuple[Cycle, SealStatus]]:
        """One robot's cycles in chain order, each with its seal check and the link to the
        previous seal (across segments and tiers; the first seal of a segment is checked
        against the previous segment's last, or its ``prev_seal`` when that is missing)."""
        prev: str | None = None
        for segment in self.segments_of(robot_id):
            if prev is None:
                prev = segment.session.prev_seal
            for cycle in segment.iter_cycles():
                status = verify_cycle(cycle, prev)
                if status.seal_digest is not None:
                    prev = status.seal_digest
                yield cycle, status

    def clear_caches(self) -> None:
        """Forget what every segment decoded lately (to measure a first read)."""
        for segment in self.segments:
            segment.clear_caches()

    @property
    def start_ns(self) -> int:
        return min(s.start_ns for s in self._timed)

    @property
    def end_ns(self) -> int:
        return max(s.end_ns for s in self._timed)

    @property
    def recovered(self) -> bool:
        return any(not s.finished for s in self.segments)

    def iter_cycles(
        self, start_ns: int | None = None, end_ns: int | None = None, *, reverse: bool = False
    ) -> Iterator[Cycle]:
        """Every cycle in time order across segments (or newest first)."""
        segments = [
            s
            for s in self.segments
            if (start_ns is None or s.end_ns >= start_ns)
            and (end_ns is None or s.start_ns <= end_ns)
        ]
        for segment in reversed(segments) if reverse else segments:
            yield from segment.iter_cycles(start_ns, end_ns, reverse=reverse)

    def cycle_at(self, t_ns: int) -> Cycle:
        """The cycle in force at ``t_ns``; ``TimeOutOfRangeError`` outside the log's range."""
        if t_ns < self.start_ns or t_ns > self.end_ns + max(
            (s.session.period_ns for s in self.segments), default=0
        ):
            raise TimeOutOfRangeError(t_ns, self.start_ns, self.end_ns)
        index = bisect.bisect_right(self._starts, t_ns)
        for segment in reversed(self.segments[:index]):
            found = segment.cycle_at(t_ns)
            if found is not None:
                return found
        raise TimeOutOfRangeError(t_ns, self.start_ns, self.end_ns)

    def get_cycle(self, number: int) -> Cycle | None:
        """The cycle with this number (a scan bounded to the segment that covers it)."""
        for segment in self.segments:
            first = segment.session.first_cycle
            if number < first:
                continue
            for cycle in segment.iter_cycles():
                if cycle.cycle == number:
                    return cycle
                if cycle.cycle > number:
                    break
        return None


def open_segments(
    files: Sequence[Path], limits: ReadLimits = DEFAULT_LIMITS
) -> tuple[list[Segment], list[FileProblem]]:
    """Open every file; those that cannot be read become problems, not failures."""
    segments: list[Segment] = []
    problems: list[FileProblem] = []
    for file in files:
        try:
            segments.append(Segment(file, limits))
        except LogReadError as err:
            problems.append(FileProblem(file, err.reason, isinstance(err, NotTraceLogError)))
    return segments, problems


def _files_of(path: Path) -> list[Path]:
    """The segment files a path names; a missing path or an empty directory is an error."""
    if not path.exists():
        raise LogReadError(str(path), "no such file or directory")
    files = find_segment_files(path)
    if not files:
        raise LogReadError(str(path), "directory holds no .mcap segments")
    return files


def open_logs(paths: Sequence[str | Path], limits: ReadLimits = DEFAULT_LIMITS) -> Log:
    """Several files, directories or roots read as one log (a fleet's metrics); a file
    named twice is read once. Unreadable files are listed in ``Log.problems``."""
    if not paths:
        raise UsageError("no log given")
    files: dict[Path, Path] = {}
    for path in map(Path, paths):
        for file in _files_of(path):
            files.setdefault(file.resolve(), file)
    segments, problems = open_segments(list(files.values()), limits)
    return Log(segments, Path(paths[0]), problems)


def open_log(path: str | Path, limits: ReadLimits = DEFAULT_LIMITS) -> Log:
    """Open a segment file, a directory of segments, or a log root (hot/ warm/ cold/).

    A single file that cannot be read raises ``LogReadError``; in a directory, unreadable
    files are listed in ``Log.problems`` (one warning each) and the others are read.
    """
    root = Path(path)
    files = _files_of(root)
    if not root.is_dir():
        return Log([Segment(root, limits)], root)
    segments, problems = open_segments(files, limits)
    opened = Log(segments, root, problems)
    for problem in opened.problems:
        what = "not a TRACE segment" if problem.foreign else "unreadable"
        log.warning("%s: %s, skipped (%s)", problem.path, what, problem.reason)
    return opened
