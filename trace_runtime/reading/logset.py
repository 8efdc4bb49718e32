"""A log of many segments: the one owner of which files make up a log, which copy of a
segment found in two tiers is read, and each robot's chain across segments.

Every reader of more than one file (``explain``, ``metrics``, ``verify``, compaction,
retention) opens logs here, so they all read the same copy of every segment and agree on
what could not be read (``Log.problems``): one unreadable file in a root is a problem to
report, not a reason to refuse the other segments.

A question about one moment (``explain``) needs one segment of a day's two dozen:
``open_log(root, lazy=True)`` takes each segment's time range from the root's catalog when
the catalog still describes every file, and opens a segment only when a query reaches it.
"""

from __future__ import annotations

import bisect
import hashlib
import itertools
import logging
import stat
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from trace_runtime.boundary import file_kind, read_side_json, tier_folder
from trace_runtime.clock import clock_restarted
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.encoding.seal_check import SealStatus, verify_cycle
from trace_runtime.errors import (
    LogReadError,
    NotTraceLogError,
    StaleCatalogError,
    TimeOutOfRangeError,
    UsageError,
)
from trace_runtime.read_limits import DEFAULT_LIMITS, ReadLimits
from trace_runtime.reading.reader import Segment
from trace_runtime.records import TOPIC_SEAL
from trace_runtime.segment_names import parse_segment_name
from trace_runtime.session import TIER_METADATA, TIERS

log = logging.getLogger("trace_runtime")
fork_log = logging.getLogger("trace_runtime.forks")
"""Where a fork (two recordings at one chain position) is warned of; a caller that refuses
forks itself (the fleet index) silences it."""


PARTIAL_MARK = ".partial"
"""File names holding this are writes in progress (compaction), never read as segments."""


@dataclass(frozen=True, slots=True)
class FileProblem:
    """A file of a log that could not be read, and why (one line)."""

    path: Path
    reason: str
    foreign: bool = False
    """The file is MCAP (or something else) that is not a TRACE segment: not damage."""


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


def find_segment_files(path: Path) -> list[Path]:
    """Segment files of a log: the file itself, or every ``*.mcap`` below a directory
    (writes in progress excluded).

    Below a directory only regular files count: a link (to a file elsewhere, or a tier folder
    that is one: ``boundary.tier_folder`` refuses it) would let the log reach outside its
    folder, and a FIFO would block the reader, so each is skipped with a warning."""
    if not path.is_dir():
        return [path]
    for tier in TIERS:
        tier_folder(path, tier)
    files: list[Path] = []
    for candidate in sorted(path.rglob("*.mcap")):
        if PARTIAL_MARK in candidate.name:
            continue
        try:
            mode = candidate.lstat().st_mode
        except OSError:
            continue  # removed while we looked
        if stat.S_ISREG(mode):
            files.append(candidate)
        elif not stat.S_ISDIR(mode):
            log.warning("%s: %s, not a segment file; skipped", candidate, file_kind(mode))
    return files


def robot_segment_files(root: Path, robot_id: str) -> dict[int, list[Path]]:
    """``robot_id``'s segment files among a log root's (``find_segment_files``), by segment
    number, known by their names (``parse_segment_name``): nothing is opened."""
    return segment_files_by_robot(root).get(robot_id, {})


def segment_files_by_robot(root: Path) -> dict[str, dict[int, list[Path]]]:
    """Every robot's segment files among a log root's, by robot (in order of name), then
    by segment number, known by their names: nothing is opened."""
    found: dict[str, dict[int, list[Path]]] = {}
    for path in find_segment_files(root):
        parsed = parse_segment_name(path.name)
        if parsed is not None:
            found.setdefault(parsed[0], {}).setdefault(parsed[1], []).append(path)
    return dict(sorted(found.items()))


@dataclass(slots=True)
class _Unopened:
    """A segment the catalog describes, opened when a query first reaches it.

    ``start_ns`` and ``end_ns`` are the catalog's; the catalog is a hint, so ``open``
    confirms them (and the robot and segment number) against the file's own summary and
    raises ``StaleCatalogError`` when they differ."""

    path: Path
    robot: str
    segment: int
    start_ns: int
    end_ns: int
    limits: ReadLimits
    opened: Segment | None = field(default=None, repr=False)

    def open(self) -> Segment:
        if self.opened is None:
            segment = Segment(self.path, self.limits)
            own = (segment.session.robot_id, segment.session.segment, segment.start_ns)
            if (*own, segment.end_ns) != (self.robot, self.segment, self.start_ns, self.end_ns):
                log.warning(
                    "%s: the root's catalog.json does not describe it as it is; the catalog "
                    "is ignored",
                    self.path,
                )
                raise StaleCatalogError(str(self.path), "not as the root's catalog.json says")
            self.opened = segment
        return self.opened


_Slot = Segment | _Unopened


def _opened(slot: _Slot) -> Segment:
    return slot if isinstance(slot, Segment) else slot.open()


def _robot_of(slot: _Slot) -> str:
    return slot.robot if isinstance(slot, _Unopened) else slot.session.robot_id


def _chain_key(slot: _Slot) -> tuple[int, str]:
    number = slot.segment if isinstance(slot, _Unopened) else slot.session.segment
    return number, slot.path.name


class Log:
    """One or more segments read as one log: per robot, in chain order, across tiers.

    A lazily opened log (``open_log(..., lazy=True)`` on a catalogued root) answers time
    queries (``cycle_at``, ``iter_cycles``, ``start_ns``, ``end_ns``, ``segment_named``) by
    opening only the segments they reach; ``segments`` and everything built on it open the
    rest on first use.
    """

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
        self._place(sorted(kept, key=lambda s: (s.start_ns, s.path.name)))
        # A segment that holds nothing (a logger opened and closed without a cycle) has no
        # time range; its zeros must not stretch the log's range back to the epoch.
        self._timed: list[_Slot] = [s for s in kept if s.holds_messages] or list(kept)
        self._recovered = any(not s.finished and not s.live for s in kept)
        self._live = any(not s.finished and s.live for s in kept)

    @classmethod
    def _catalogued(cls, slots: Sequence[_Unopened], root: Path) -> Log:
        """A log of finished segments that each hold messages, one copy each (what
        ``_catalogued_slots`` admits), none of them opened yet."""
        log = cls.__new__(cls)
        log.root, log.problems, log.shadowed = root, [], []
        log._place(sorted(slots, key=lambda s: (s.start_ns, s.path.name)))
        log._timed = list(log._slots)
        log._recovered = log._live = False
        return log

    def clock_run(self, segment_name: str) -> Log:
        """The log cut to one robot's run of segments around ``segment_name`` whose times
        follow on from one another.

        A robot restarted with a monotonic clock starts its times again lower (PROFILE
        section 4 allows it across segments), so one time can name decisions of two runs;
        a walk back in time from a decision must stay in its own run. The log itself when
        it is one robot's and its clock never went back."""
        runs = self._clock_runs()
        run = next((r for r in runs if any(s.path.name == segment_name for s in r)), None)
        if run is None or len(run) == len(self._slots):
            return self
        return self._of_run(run)

    def clock_runs(self) -> list[Log]:
        """The log cut into the runs of its robots' clocks (``clock_run``), each robot's in
        chain order; ``[self]`` when it is one robot's and its clock never went back."""
        runs = self._clock_runs()
        return [self] if len(runs) == 1 else [self._of_run(run) for run in runs]

    def _clock_runs(self) -> list[list[_Slot]]:
        """Each robot's segments in chain order, split where the clock restarted between two
        (``clock_restarted``: a segment ends after the next one starts)."""
        by_robot: dict[str, list[_Slot]] = {}
        for slot in self._slots:
            by_robot.setdefault(_robot_of(slot), []).append(slot)
        runs: list[list[_Slot]] = []
        for robot in sorted(by_robot):
            chain = sorted(by_robot[robot], key=_chain_key)
            run = [chain[0]]
            for before, after in itertools.pairwise(chain):
                if clock_restarted(before.end_ns, after.start_ns):
                    runs.append(run)
                    run = []
                run.append(after)
            runs.append(run)
        return runs

    def _of_run(self, run: list[_Slot]) -> Log:
        log = Log.__new__(Log)
        log.root, log.problems, log.shadowed = self.root, list(self.problems), []
        log._place(sorted(run, key=lambda s: (s.start_ns, s.path.name)))
        timed = [s for s in run if isinstance(s, _Unopened) or s.holds_messages]
        log._timed = timed or list(run)
        opened = [s for s in run if isinstance(s, Segment) and not s.finished]
        log._recovered = any(not s.live for s in opened)
        log._live = any(s.live for s in opened)
        return log

    def _place(self, slots: Sequence[_Slot]) -> None:
        self._slots = list(slots)
        self._starts = [s.start_ns for s in self._slots]
        opened = [s for s in self._slots if isinstance(s, Segment)]
        self._all: list[Segment] | None = opened if len(opened) == len(self._slots) else None

    @property
    def segments(self) -> list[Segment]:
        """Every segment read, by start time (a lazily opened log opens them all here)."""
        if self._all is None:
            self._all = [_opened(s) for s in self._slots]
        return self._all

    @property
    def robots(self) -> list[str]:
        """The robots whose segments make up the log, sorted (known without opening a
        catalogued segment)."""
        return sorted({_robot_of(s) for s in self._slots})

    def of_robots(self, robots: Sequence[str]) -> Log:
        """The log cut to these robots' segments (the log itself when it holds no other).

        ``UsageError`` names the robots the log holds when one asked for is not among them."""
        held = self.robots
        missing = [repr(r) for r in dict.fromkeys(robots) if r not in held]
        if missing:
            raise UsageError(
                f"robot {', '.join(missing)} is not in this log; it holds {', '.join(held)}"
            )
        if set(held) <= set(robots):
            return self
        cut = self._of_run([s for s in self._slots if _robot_of(s) in robots])
        cut.shadowed = [s for s in self.shadowed if s.session.robot_id in robots]
        # A file that did not open is kept unless its name says it is another robot's.
        cut.problems = [
            p
            for p in self.problems
            if (named := parse_segment_name(p.path.name)) is None or named[0] in robots
        ]
        return cut

    @property
    def clock(self) -> str:
        """The clock behind the log's times (``SessionInfo.clock``) as its earliest segment
        names it; ``trace_runtime.clock.is_wall_clock`` says whether it tells the time of
        day. One robot's segments share a clock; so do a fleet's, as a rule."""
        return _opened(min(self._timed, key=lambda s: s.start_ns)).session.clock

    @property
    def first_robot(self) -> str:
        """The robot of the log's earliest segment."""
        first = self._slots[0]
        return first.robot if isinstance(first, _Unopened) else first.session.robot_id

    def segment_named(self, name: str) -> Segment | None:
        """The segment read from a file of this name (the name a ``Cycle`` carries)."""
        slot = next((s for s in self._slots if s.path.name == name), None)
        return None if slot is None else _opened(slot)

    def holds_trace_messages(self) -> bool:
        """Whether a segment's summary counts any message on a ``/trace/`` topic (False
        also when no segment has a summary: a scan must decide)."""
        if self._all is None:
            return True  # the catalog admits only segments that hold sealed cycles
        for segment in self._all:
            counts = segment.info.channels
            if any(n > 0 for topic, n in counts.items() if topic.startswith("/trace/")):
                return True
        return False

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
        for slot in self._slots:
            if isinstance(slot, Segment):
                slot.clear_caches()
            elif slot.opened is not None:
                slot.opened.clear_caches()

    @property
    def start_ns(self) -> int:
        return min(s.start_ns for s in self._timed)

    @property
    def end_ns(self) -> int:
        return max(s.end_ns for s in self._timed)

    @property
    def period_ns(self) -> int:
        """The longest cycle period of any segment (0 for none)."""
        return max((s.session.period_ns for s in self.segments), default=0)

    @property
    def recovered(self) -> bool:
        """A segment has no footer and no logger writing it: read by scan after a crash."""
        return self._recovered

    @property
    def live(self) -> bool:
        """A segment is being written right now (its logger holds the writer lock)."""
        return self._live

    def iter_cycles(
        self,
        start_ns: int | None = None,
        end_ns: int | None = None,
        *,
        reverse: bool = False,
        robot: str | None = None,
    ) -> Iterator[Cycle]:
        """Every cycle in time order across segments (or newest first); ``robot``: only that
        robot's (``of_robots`` says which robots there are)."""
        if robot is not None:
            yield from self.of_robots([robot]).iter_cycles(start_ns, end_ns, reverse=reverse)
            return
        slots = [
            s
            for s in self._slots
            if (start_ns is None or s.end_ns >= start_ns)
            and (end_ns is None or s.start_ns <= end_ns)
        ]
        for slot in reversed(slots) if reverse else slots:
            yield from _opened(slot).iter_cycles(start_ns, end_ns, reverse=reverse)

    def cycle_at(self, t_ns: int) -> Cycle:
        """The cycle in force at ``t_ns``; ``TimeOutOfRangeError`` outside the log's range."""
        start, end = self.start_ns, self.end_ns
        # A time up to one period past the last cycle is still that cycle's; the periods
        # (every segment's) are read only for such a time.
        if t_ns < start or (t_ns > end and t_ns > end + self.period_ns):
            self._confirm_range()
            raise TimeOutOfRangeError(t_ns, start, end, self.clock)
        candidates = self._slots[: bisect.bisect_right(self._starts, t_ns)]
        # A segment whose span holds t first: after a restart with a monotonic clock, a later
        # run starting lower must not answer for a time only the earlier run reached.
        spanning = [s for s in candidates if t_ns <= s.end_ns]
        for slot in [*reversed(spanning), *reversed(candidates)]:
            found = _opened(slot).cycle_at(t_ns)
            if found is not None:
                return found
        raise TimeOutOfRangeError(t_ns, start, end, self.clock)

    def _confirm_range(self) -> None:
        """Before a lazily opened log refuses a time, open the segments its range comes
        from, so that a catalog row cannot narrow the log (``StaleCatalogError``)."""
        if self._all is None:
            _opened(min(self._timed, key=lambda s: s.start_ns))
            _opened(max(self._timed, key=lambda s: s.end_ns))

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


def open_log(path: str | Path, limits: ReadLimits = DEFAULT_LIMITS, *, lazy: bool = False) -> Log:
    """Open a segment file, a directory of segments, or a log root (hot/ warm/ cold/).

    A single file that cannot be read raises ``LogReadError``; in a directory, unreadable
    files are listed in ``Log.problems`` (one warning each) and the others are read.

    ``lazy``: for a query about one moment. When the root's catalog still describes every
    segment file (``_catalogued_slots``), no segment is opened until a query reaches it;
    otherwise every segment is opened, as without it.
    """
    root = Path(path)
    files = _files_of(root)
    if not root.is_dir():
        return Log([Segment(root, limits)], root)
    if lazy:
        slots = _catalogued_slots(root, files, limits)
        if slots is not None:
            return Log._catalogued(slots, root)
    segments, problems = open_segments(files, limits)
    opened = Log(segments, root, problems)
    for problem in opened.problems:
        what = "not a TRACE segment" if problem.foreign else "unreadable"
        log.warning("%s: %s, skipped (%s)", problem.path, what, problem.reason)
    return opened


def _catalogued_slots(
    root: Path, files: Sequence[Path], limits: ReadLimits
) -> list[_Unopened] | None:
    """The segments of a log root as its catalog describes them, or None when opening
    them all is the only way to be sure what they are.

    The catalog is trusted only when its rows are exactly the files found, each with the
    size and modification time it had when its row was made, and when every row is simple
    enough that opening the files would add nothing: one copy of each segment (no copy in
    two tiers to choose between), finished, holding sealed cycles, and no file the catalog
    could not read (opening would make it a problem to report).
    """
    catalog = _catalog_rows(root)
    if catalog is None or len(catalog) != len(files):
        return None
    rows = {row["path"]: row for row in catalog}
    copies = {(row["robot"], row["segment"]) for row in catalog}
    if len(rows) != len(files) or len(copies) != len(rows):
        return None
    slots: list[_Unopened] = []
    for file in files:
        try:
            row = rows.get(file.relative_to(root).as_posix())
            stat = file.stat()
        except (ValueError, OSError):
            return None
        if (
            row is None
            or row["bytes"] != stat.st_size
            or row["mtime_ns"] != stat.st_mtime_ns
            or row["finished"] is not True
            or row["cycles"] <= 0
        ):
            return None
        slots.append(
            _Unopened(file, row["robot"], row["segment"], row["start_ns"], row["end_ns"], limits)
        )
    return slots


_CATALOG_NAME = "catalog.json"
_CATALOG_FORMAT = "trace-catalog-v1"
_CATALOG_FIELDS = {
    "path": str,
    "robot": str,
    "segment": int,
    "start_ns": int,
    "end_ns": int,
    "finished": bool,
    "cycles": int,
    "bytes": int,
    "mtime_ns": int,
}


def _catalog_rows(root: Path) -> list[dict[str, Any]] | None:
    """The rows of a root's catalog (``trace_runtime.tiers.catalog``), the fields a lazy log
    needs checked for type, or None when there is no catalog that is whole and clean.

    Read here rather than through ``tiers.catalog.load_catalog`` because importing the tiers
    package loads the writer and the ``mcap`` library (~30 ms) into every ``explain``; a test
    pins these rows to ``load_catalog``'s entries.
    """
    try:
        body = read_side_json(root / _CATALOG_NAME)
    except LogReadError:
        return None  # a hint that cannot be read is no hint: every segment is opened
    if not isinstance(body, dict) or body.get("format") != _CATALOG_FORMAT or body.get("problems"):
        return None
    rows = body.get("segments")
    if not isinstance(rows, list):
        return None
    for row in rows:
        if not isinstance(row, dict) or not all(
            type(row.get(name)) is kind for name, kind in _CATALOG_FIELDS.items()
        ):
            return None
    return rows
