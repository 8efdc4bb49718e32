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
import itertools
import logging
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from trace_runtime.clock import ClockStep, clock_restarted
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.encoding.seal_check import SealStatus, verify_cycle
from trace_runtime.errors import (
    LogReadError,
    NotTraceLogError,
    TimeOutOfRangeError,
    UsageError,
)
from trace_runtime.read_limits import DEFAULT_LIMITS, ReadLimits
from trace_runtime.reading.catalogued import (
    Slot,
    Unopened,
    catalogued_slots,
    chain_key,
    open_slot,
    robot_of,
)
from trace_runtime.reading.copies import preferred_copies
from trace_runtime.reading.reader import Segment
from trace_runtime.reading.segment_files import files_of
from trace_runtime.records import LAYER_TOPICS, TOPIC_SEAL
from trace_runtime.segment_names import parse_segment_name
from trace_runtime.tier_formats.warm import SUMMARY_TOPIC

log = logging.getLogger("trace_runtime")

_CYCLE_TOPICS = (*LAYER_TOPICS, TOPIC_SEAL, SUMMARY_TOPIC)
"""The topics a decision cycle's messages are on (a checkpoint's is not one of them)."""


@dataclass(frozen=True, slots=True)
class FileProblem:
    """A file of a log that could not be read, and why (one line)."""

    path: Path
    reason: str
    foreign: bool = False
    """The file is MCAP (or something else) that is not a TRACE segment: not damage."""


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
        self._timed: list[Slot] = [s for s in kept if s.holds_messages] or list(kept)
        self._recovered = any(not s.finished and not s.live for s in kept)
        self._live = any(not s.finished and s.live for s in kept)

    @classmethod
    def _catalogued(cls, slots: Sequence[Unopened], root: Path) -> Log:
        """A log of finished segments that each hold messages, one copy each (what
        ``catalogued_slots`` admits), none of them opened yet."""
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

    def clock_steps(self) -> list[ClockStep]:
        """Where each robot's clock went back between two of its segments (the boundaries of
        ``clock_runs``), robot by robot in chain order; opens only the segments after them."""
        steps: list[ClockStep] = []
        for before, after in itertools.pairwise(self._clock_runs()):
            if robot_of(before[-1]) != robot_of(after[0]):
                continue
            session = open_slot(after[0]).session
            declared = session.clock_step_from_ns
            steps.append(
                ClockStep(
                    robot_id=session.robot_id,
                    segment=after[0].path.name,
                    segment_no=session.segment,
                    first_cycle=session.first_cycle,
                    from_ns=before[-1].end_ns if declared is None else declared,
                    to_ns=after[0].start_ns,
                    declared=declared is not None,
                )
            )
        return steps

    def _clock_runs(self) -> list[list[Slot]]:
        """Each robot's segments in chain order, split where the clock restarted between two
        (``clock_restarted``: a segment ends after the next one starts)."""
        by_robot: dict[str, list[Slot]] = {}
        for slot in self._slots:
            by_robot.setdefault(robot_of(slot), []).append(slot)
        runs: list[list[Slot]] = []
        for robot in sorted(by_robot):
            chain = sorted(by_robot[robot], key=chain_key)
            run = [chain[0]]
            for before, after in itertools.pairwise(chain):
                if clock_restarted(before.end_ns, after.start_ns):
                    runs.append(run)
                    run = []
                run.append(after)
            runs.append(run)
        return runs

    def _of_run(self, run: list[Slot]) -> Log:
        log = Log.__new__(Log)
        log.root, log.problems, log.shadowed = self.root, list(self.problems), []
        log._place(sorted(run, key=lambda s: (s.start_ns, s.path.name)))
        timed = [s for s in run if isinstance(s, Unopened) or s.holds_messages]
        log._timed = timed or list(run)
        opened = [s for s in run if isinstance(s, Segment) and not s.finished]
        log._recovered = any(not s.live for s in opened)
        log._live = any(s.live for s in opened)
        return log

    def _place(self, slots: Sequence[Slot]) -> None:
        self._slots = list(slots)
        self._starts = [s.start_ns for s in self._slots]
        opened = [s for s in self._slots if isinstance(s, Segment)]
        self._all: list[Segment] | None = opened if len(opened) == len(self._slots) else None

    @property
    def segments(self) -> list[Segment]:
        """Every segment read, by start time (a lazily opened log opens them all here)."""
        if self._all is None:
            self._all = [open_slot(s) for s in self._slots]
        return self._all

    @property
    def robots(self) -> list[str]:
        """The robots whose segments make up the log, sorted (known without opening a
        catalogued segment)."""
        return sorted({robot_of(s) for s in self._slots})

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
        cut = self._of_run([s for s in self._slots if robot_of(s) in robots])
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
        return open_slot(min(self._timed, key=lambda s: s.start_ns)).session.clock

    @property
    def first_robot(self) -> str:
        """The robot of the log's earliest segment."""
        first = self._slots[0]
        return first.robot if isinstance(first, Unopened) else first.session.robot_id

    def segment_named(self, name: str) -> Segment | None:
        """The segment read from a file of this name (the name a ``Cycle`` carries)."""
        slot = next((s for s in self._slots if s.path.name == name), None)
        return None if slot is None else open_slot(slot)

    def holds_cycle_messages(self) -> bool:
        """Whether a segment's summary counts any message of a decision cycle (a layer, a
        seal or a warm summary; a checkpoint is not one). False also when no segment has
        a summary: a scan must decide."""
        if self._all is None:
            return True  # the catalog admits only segments that hold sealed cycles
        for segment in self._all:
            counts = segment.info.channels
            if any(counts.get(topic, 0) > 0 for topic in _CYCLE_TOPICS):
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
            yield from open_slot(slot).iter_cycles(start_ns, end_ns, reverse=reverse)

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
            found = open_slot(slot).cycle_at(t_ns)
            if found is not None:
                return found
        raise TimeOutOfRangeError(t_ns, start, end, self.clock)

    def _confirm_range(self) -> None:
        """Before a lazily opened log refuses a time, open the segments its range comes
        from, so that a catalog row cannot narrow the log (``StaleCatalogError``)."""
        if self._all is None:
            open_slot(min(self._timed, key=lambda s: s.start_ns))
            open_slot(max(self._timed, key=lambda s: s.end_ns))

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


def open_logs(paths: Sequence[str | Path], limits: ReadLimits = DEFAULT_LIMITS) -> Log:
    """Several files, directories or roots read as one log (a fleet's metrics); a file
    named twice is read once. Unreadable files are listed in ``Log.problems``."""
    if not paths:
        raise UsageError("no log given")
    files: dict[Path, Path] = {}
    for path in map(Path, paths):
        for file in files_of(path):
            files.setdefault(file.resolve(), file)
    segments, problems = open_segments(list(files.values()), limits)
    return Log(segments, Path(paths[0]), problems)


def open_log(path: str | Path, limits: ReadLimits = DEFAULT_LIMITS, *, lazy: bool = False) -> Log:
    """Open a segment file, a directory of segments, or a log root (hot/ warm/ cold/).

    A single file that cannot be read raises ``LogReadError``; in a directory, unreadable
    files are listed in ``Log.problems`` (one warning each) and the others are read.

    ``lazy``: for a query about one moment. When the root's catalog still describes every
    segment file (``catalogued_slots``), no segment is opened until a query reaches it;
    otherwise every segment is opened, as without it.
    """
    root = Path(path)
    files = files_of(root)
    if not root.is_dir():
        return Log([Segment(root, limits)], root)
    if lazy:
        slots = catalogued_slots(root, files, limits)
        if slots is not None:
            return Log._catalogued(slots, root)
    segments, problems = open_segments(files, limits)
    opened = Log(segments, root, problems)
    for problem in opened.problems:
        what = "not a TRACE segment" if problem.foreign else "unreadable"
        log.warning("%s: %s, skipped (%s)", problem.path, what, problem.reason)
    return opened
