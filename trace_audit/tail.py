"""Decision changes as they are written: a log root followed like ``journalctl -f``.

A *decision change* is what the timeline calls one (``trace_audit.transitions``): a cycle whose
command differs from the previous cycle's of the same robot; a robot's first cycle read opens
with one too (``previous`` None). ``tail`` reads each robot's newest segment (the one being
written, or the last one written), yields its decision changes, and with ``follow`` polls for
what is new, moving on to the next segment when the logger rotates.

What it remembers is bounded however long it runs: per robot, the segment it reads and where
in it the last complete record read ends
(``trace_runtime.reading.growing_file.GrowingSegment``), the last cycle number and time
read, and the last command. Each poll reads only the bytes the logger appended since the last
one, a chunk at a time; a chunk still being written is read
at the next poll. Whether a segment is being written is the writer lock's answer
(``trace_runtime.live_writers``), looked up, never taken: a segment without a footer whose
writer is gone is shown as recovered, one whose writer holds its lock as live.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path

from trace_audit.causal import FactorValue, read_decision
from trace_audit.cycle_fields import command_of, seal_dropped
from trace_audit.log_time import SECONDS_CLOCK, LogClock
from trace_audit.selection import Selection
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.errors import LogReadError, NotHotSegmentError, UsageError
from trace_runtime.gaps import GapFinder, SealedStamp
from trace_runtime.live_writers import is_live
from trace_runtime.reading.copies import preferred_copies
from trace_runtime.reading.growing_file import GrowingSegment
from trace_runtime.reading.logset import open_log
from trace_runtime.reading.reader import RECOVERED_WARNING, Segment
from trace_runtime.reading.segment_files import segment_files_by_robot

__all__ = [
    "DEFAULT_POLL_S",
    "DecisionChange",
    "LogGap",
    "SegmentState",
    "SegmentStatus",
    "TailEvent",
    "tail",
]

DEFAULT_POLL_S = 0.2
"""How often a followed log is looked at: a logger writes a chunk a batch (10 Hz by default),
so a change shows within about one batch of its write."""


class SegmentStatus(Enum):
    """What a segment is to its reader right now."""

    LIVE = "live"
    """No footer yet, and its writer holds the lock: being written."""
    FINISHED = "finished"
    """Closed by its logger (a footer)."""
    RECOVERED = "recovered"
    """No footer, and no writer: the logger died; read up to its last complete chunk."""


@dataclass(frozen=True, slots=True)
class SegmentState:
    """The segment a robot's changes are read from, when tail starts on it, moves to it or
    its state changes (a writer that dies: live to recovered; a logger that closes it)."""

    robot: str
    segment: str
    status: SegmentStatus
    kind: str = field(default="segment", init=False)


@dataclass(frozen=True, slots=True)
class DecisionChange:
    """A cycle whose command differs from the robot's previous cycle's, with its reason."""

    robot: str
    segment: str
    cycle: int
    t_ns: int
    command: str | None
    previous: str | None
    """The command before (None: the first cycle tail read of this robot)."""
    rationale: str | None
    leading: FactorValue | None
    """The leading factor: the first the rationale names."""
    clock: LogClock = SECONDS_CLOCK
    kind: str = field(default="change", init=False)

    @property
    def shown_t(self) -> str:
        return self.clock.show(self.t_ns)


@dataclass(frozen=True, slots=True)
class LogGap:
    """Time without a logged cycle beyond what the period allows, by the one gap rule
    (``trace_runtime.gaps``, as ``timeline`` and ``info`` find gaps): yielded at the sealed
    cycle that ends it, before that cycle's decision change if it has one, so a change right
    after a gap never reads as a direct one."""

    robot: str
    segment: str
    after_cycle: int
    """The last sealed cycle before the gap."""
    cycle: int
    """The first sealed cycle after it."""
    t_ns: int
    """The time of ``cycle``."""
    gap_ns: int
    """Time beyond one period (what TC counts as lost)."""
    missing_cycles: int
    """Cycles the gap would have held at the nominal period."""
    declared_dropped: int | None
    """Cycles the seal after the gap declares dropped."""
    clock: LogClock = SECONDS_CLOCK
    kind: str = field(default="gap", init=False)

    @property
    def shown_t(self) -> str:
        return self.clock.show(self.t_ns)

    @property
    def not_logged(self) -> str:
        """Which cycles the log lacks: their numbers, or none when the numbers run on (a
        stall: the robot did not cycle, nothing was lost)."""
        first, last = self.after_cycle + 1, self.cycle - 1
        if last < first:
            return f"no cycle number skipped between {self.after_cycle} and {self.cycle}"
        numbers = f"cycle {first}" if first == last else f"cycles {first}..{last}"
        declared = self.declared_dropped
        said = "" if not declared else f", {declared} declared dropped by the logger"
        return f"{numbers} not logged{said}"


TailEvent = DecisionChange | LogGap | SegmentState


@dataclass(slots=True)
class _Robot:
    """What tail remembers of one robot: a fixed handful of fields, however long it runs."""

    name: str
    clock: LogClock | None = None
    number: int = -1
    path: Path | None = None
    reader: GrowingSegment | None = None
    """The segment followed (None once read whole: a warm or cold one, never appended to)."""
    status: SegmentStatus | None = None
    last_cycle: int | None = None
    last_t_ns: int | None = None
    command: str | None = None
    seen_any: bool = False
    gaps: GapFinder = field(default_factory=GapFinder)
    """The one gap rule, remembering this robot's last sealed cycle (across rotations)."""
    on_cycle: Callable[[str, Cycle], None] | None = None


class _QuietRecovered(logging.Filter):
    """The state of a segment is tail's own event (``SegmentState``): the reader's "recovered"
    warning, logged when a copy of a segment is opened to choose between copies, is not
    repeated beside it."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.msg != RECOVERED_WARNING


def tail(
    root: str | Path,
    *,
    robots: Sequence[str] = (),
    follow: bool = False,
    poll_s: float = DEFAULT_POLL_S,
    stop: threading.Event | None = None,
    on_cycle: Callable[[str, Cycle], None] | None = None,
) -> Iterator[TailEvent]:
    """Each robot's decision changes from its newest segment on, as ``SegmentState`` and
    ``DecisionChange`` events; with ``follow``, polling every ``poll_s`` for what is new
    until ``stop`` is set (without, once through what is written so far). ``on_cycle`` is
    given every sealed cycle read, with its robot, before the events it makes (the live
    Foxglove view, ``foxglove.live``, shows each one).

    ``robots`` selects robots (``selection.Selection``; one not in the log is a
    ``UsageError``, but followed it is waited for: tail is started before the robot boots);
    none follows every robot, including robots that start logging later. A root that does
    not exist yet is, followed, waited for (like ``tail -F``): the robot creates it."""
    path = Path(root)
    stop = stop or threading.Event()
    if follow:
        while not path.exists():
            if stop.wait(poll_s):
                return
    if not path.exists():
        raise LogReadError(str(path), "no such file or directory")
    if not path.is_dir():
        raise UsageError(f"{path}: tail follows a log root (a folder), not one file")
    chosen = tuple(dict.fromkeys(robots)) if follow else _selected(path, robots)
    if not follow and not _newest_segments(path, chosen):
        # Nothing to print is not "no change": a root holding no readable segment (only
        # a file that is not MCAP, or nothing) is the reader's one error (exit 3), as info's.
        open_log(path, lazy=True)
    state: dict[str, _Robot] = {}
    quiet = _QuietRecovered()
    reader_log = logging.getLogger("trace_runtime")
    reader_log.addFilter(quiet)
    try:
        while True:
            began = time.monotonic()
            for name, numbered in _newest_segments(path, chosen).items():
                robot = state.setdefault(name, _Robot(name, on_cycle=on_cycle))
                yield from _read_robot(robot, numbered)
            # A pass reads only what was appended; still, never poll faster than a pass
            # takes (a burst of appended chunks, a slow disk): at most half a core.
            if not follow or stop.wait(max(poll_s, time.monotonic() - began)):
                return
    finally:
        reader_log.removeFilter(quiet)


def _selected(root: Path, robots: Sequence[str]) -> tuple[str, ...]:
    """The robots asked for, checked against the log (``()``: every robot, found anew at
    each poll). An empty root has no robots yet: followed, robots appear as they log."""
    if not robots:
        return ()
    log = Selection(tuple(robots)).of(open_log(root, lazy=True))
    return tuple(log.robots)


def _newest_segments(root: Path, robots: tuple[str, ...]) -> dict[str, dict[int, list[Path]]]:
    """Each selected robot's segment files by number, known by their names (nothing opened)."""
    found = segment_files_by_robot(root)
    return {robot: files for robot, files in found.items() if not robots or robot in robots}


def _read_robot(robot: _Robot, numbered: dict[int, list[Path]]) -> Iterator[TailEvent]:
    """What is new in one robot's segments: the rest of the one read so far, then each later
    one in turn (a rotation); a robot met for the first time starts at its newest."""
    if robot.path is None:
        robot.number = max(numbered) - 1
    newer = sorted(n for n in numbered if n > robot.number)
    if robot.path is not None:
        yield from _read_segment(robot, robot.path)
    for number in newer:
        chosen = _copy_of(numbered[number])
        if chosen is None:
            continue
        robot.number, robot.path, robot.status = number, chosen, None
        robot.reader = GrowingSegment(chosen)
        robot.last_cycle = robot.last_t_ns = None
        yield from _read_segment(robot, chosen)


def _copy_of(copies: list[Path]) -> Path | None:
    """The copy of a segment to read (``copies.preferred_copies`` when there are several)."""
    if len(copies) == 1:
        return copies[0]
    opened: list[Segment] = []
    for copy in copies:
        try:
            opened.append(Segment(copy))
        except LogReadError:
            continue
    kept, _ = preferred_copies(opened)
    return kept[0].path if kept else None


def _read_segment(robot: _Robot, path: Path) -> Iterator[TailEvent]:
    """The decision changes appended to ``path`` since the last poll, and its state when
    that changed: live while its writer holds the lock, finished once its footer is read,
    recovered when the writer is gone without one (a kill -9 turns it from live to
    recovered without a byte written)."""
    reader = robot.reader
    if reader is None:
        return  # read whole already (a warm or cold segment): nothing is appended to it
    if robot.status is None:
        status = _status(robot, reader, path)
        if status is None:
            return  # removed, or moved away (compaction): the next poll finds what replaced it
        robot.status = status
        yield SegmentState(robot.name, path.name, status)
    try:
        yield from _changes(robot, reader.poll(), reader)
    except NotHotSegmentError:
        robot.reader = None
        yield from _read_whole(robot, path)
        return
    except LogReadError:
        return  # moved away, or unreadable past here: the next segment is read when it comes
    status = _status(robot, reader, path)
    if status is not None and status is not robot.status:
        robot.status = status
        yield SegmentState(robot.name, path.name, status)


def _status(robot: _Robot, reader: GrowingSegment, path: Path) -> SegmentStatus | None:
    """What the segment is now (None: it is gone). A writer that is gone is told from one
    that just closed the file by its footer: recovered only without one."""
    if reader.finished:
        return SegmentStatus.FINISHED
    if robot.status is SegmentStatus.RECOVERED:
        return robot.status  # its writer is gone: no one appends to it again
    if not path.exists():
        return None
    if is_live(path, robot.name):
        return SegmentStatus.LIVE
    if reader.has_footer():
        # closed, and its lock let go, since the last read: finished as read at first
        # sight, or at the next poll (which reads the rest of it first)
        return SegmentStatus.FINISHED if robot.status is None else robot.status
    return SegmentStatus.RECOVERED


def _read_whole(robot: _Robot, path: Path) -> Iterator[TailEvent]:
    """A warm or cold segment (rewritten whole by compaction): its changes, read once."""
    try:
        segment = Segment(path)
    except LogReadError:
        return
    if robot.clock is None:
        robot.clock = LogClock(segment.session.clock, segment.start_ns)
    if robot.status is not SegmentStatus.FINISHED:
        robot.status = SegmentStatus.FINISHED
        yield SegmentState(robot.name, path.name, robot.status)
    period_ns = segment.session.period_ns
    yield from _changes(robot, segment.iter_cycles(start_ns=robot.last_t_ns), None, period_ns)


def _changes(
    robot: _Robot,
    cycles: Iterator[Cycle],
    reader: GrowingSegment | None,
    period_ns: int = 0,
) -> Iterator[DecisionChange | LogGap]:
    """The gaps and decision changes among sealed cycles not read before (by cycle number).
    A followed segment's session and start are known once its first records are read:
    before its first cycle comes."""
    for cycle in cycles:
        if not cycle.sealed:
            continue  # its seal was lost (a cycle the logger never sealed)
        if robot.last_cycle is not None and cycle.cycle <= robot.last_cycle:
            continue
        if reader is not None and reader.session is not None:
            period_ns = reader.session.period_ns
            if robot.clock is None:
                robot.clock = LogClock(reader.session.clock, reader.start_ns or cycle.t_ns)
        robot.last_cycle, robot.last_t_ns = cycle.cycle, cycle.t_ns
        if robot.on_cycle is not None:
            robot.on_cycle(robot.name, cycle)
        stamp = SealedStamp(cycle.cycle, cycle.t_ns, period_ns, seal_dropped(cycle))
        gap = robot.gaps.step(robot.name, stamp)
        if gap is not None:
            yield LogGap(
                robot.name,
                cycle.segment,
                gap.after_cycle,
                gap.before_cycle,
                gap.before_t_ns,
                gap.gap_ns,
                gap.missing_cycles,
                gap.declared_dropped,
                robot.clock or SECONDS_CLOCK,
            )
        command = command_of(cycle)
        if robot.seen_any and command == robot.command:
            continue
        previous, robot.command = robot.command if robot.seen_any else None, command
        robot.seen_any = True
        decision = read_decision(cycle, with_tree=False)
        yield DecisionChange(
            robot.name,
            cycle.segment,
            cycle.cycle,
            cycle.t_ns,
            command,
            previous,
            decision.rationale,
            decision.leading,
            robot.clock or SECONDS_CLOCK,
        )
