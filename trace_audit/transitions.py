"""Decisions over time: the timeline of decision changes, and why the robot took an action.

Times are read as ``trace_audit.log_time`` says (int ns in the log's clock, or CLI text).

A *decision change* is a cycle whose command differs from the previous logged cycle's. The
first cycle of a window always opens a row. Cycles that were never logged (dropped, a gap in
time) are reported as gaps between rows, not papered over.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

from trace_audit.causal import CounterfactualView, FactorValue, read_decision
from trace_audit.cycle_fields import command_of, execution_fields, is_decision_change
from trace_audit.jsonout import OMIT_EMPTY
from trace_audit.log_gaps import gap_stepper
from trace_audit.log_source import LogSource, as_log, require_cycles
from trace_audit.log_time import SECONDS_CLOCK, LogClock, TimeArg, resolve_time
from trace_audit.selection import Selection, SeveralRobotsError
from trace_runtime.clock import ClockStep, offset_hint
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.errors import UsageError
from trace_runtime.flags import split_flags
from trace_runtime.gaps import DEFAULT_GAP_TOLERANCE, Gap
from trace_runtime.reading.logset import Log

__all__ = [
    "ActionNotTakenError",
    "ClockRun",
    "Gap",
    "Timeline",
    "TimelineRow",
    "Transition",
    "WhyResult",
    "WindowOutsideLogError",
    "one_robot",
    "timeline",
    "why",
]


def _period_ns(log: Log) -> int:
    return max((s.session.period_ns for s in log.segments), default=0)


# --- timeline ------------------------------------------------------------------------------


@dataclass(slots=True)
class TimelineRow:
    """A stretch of cycles with one command: the cycle that began it and what it held.

    ``held_ns`` runs from this cycle to the next row's (or one period past the last cycle
    of the window), so back-to-back rows add up to the window.
    """

    cycle: int
    t_ns: int
    command: str | None
    previous: str | None
    leading: FactorValue | None
    rationale: str | None
    flags: tuple[str, ...]
    end_cycle: int
    end_t_ns: int
    cycles: int = 0
    held_ns: int = 0
    scenario: str | None = None
    flagged_cycles: int = 0
    flag_counts: dict[str, int] = field(default_factory=dict)
    """Flags raised while the command held (``scenario:`` labels left out), with counts."""
    max_deviation: float | None = field(default=None, metadata={OMIT_EMPTY: True})
    """The largest overall execution deviation while the command held, when the records
    name its unit (``deviation_unit``, profile 1.1)."""
    deviation_unit: str | None = field(default=None, metadata={OMIT_EMPTY: True})
    run: int | None = field(default=None, metadata={OMIT_EMPTY: True})
    """Which run of the robot's clock (``Timeline.clock_runs``, from 0) holds the row, when
    its clock restarted in the log."""


@dataclass(frozen=True, slots=True)
class ClockRun:
    """A run of segments whose times follow on from one another (a restart with a monotonic
    clock starts the next one lower: PROFILE section 4)."""

    segments: tuple[str, ...]
    first_cycle: int | None
    last_cycle: int | None
    cycles: int


@dataclass(frozen=True, slots=True)
class Timeline:
    """Rows of decision changes (or of every cycle) in a window, with the gaps between the
    sealed cycles of each robot (``trace_runtime.gaps``, the rule metrics uses for TC)."""

    path: str
    robot: str
    start_ns: int
    end_ns: int
    every: bool
    cycles: int
    changes: int
    rows: tuple[TimelineRow, ...]
    gaps: tuple[Gap, ...]
    recovered: bool
    clock_runs: tuple[ClockRun, ...] = field(default=(), metadata={OMIT_EMPTY: True})
    """When the robot's clock restarted in the log: its runs, in chain order; the rows and
    gaps of each run are its own (a run's first row is no decision change). Empty else."""
    live: bool | None = field(default=None, metadata={OMIT_EMPTY: True})
    """True when a segment of the log is being written right now; left out of JSON else."""
    clock: LogClock = SECONDS_CLOCK
    """The log's clock and first time: how its times are shown (``log_time.LogClock``)."""
    clock_steps: tuple[ClockStep, ...] = field(default=(), metadata={OMIT_EMPTY: True})
    """Where the clock went back between the runs: a step its writer declared (chrony, a
    replay's ``/clock``), or a restart on a clock that begins lower."""


class WindowOutsideLogError(UsageError):
    """The asked window holds none of the log's time."""


def _window(log: Log, start: TimeArg, end: TimeArg) -> tuple[int, int]:
    start_ns = resolve_time(start, log)
    end_ns = resolve_time(end, log)
    lo = log.start_ns if start_ns is None else start_ns
    hi = log.end_ns if end_ns is None else end_ns
    clock = LogClock.of(log)
    if start_ns is not None and end_ns is not None and end_ns < start_ns:
        raise UsageError(f"the window ends before it starts ({clock.show(lo)} > {clock.show(hi)})")
    if lo > log.end_ns or hi < log.start_ns or hi < lo:
        raise WindowOutsideLogError(
            f"the window [{clock.show(lo)}, {clock.show(hi)}] does not overlap the log's "
            f"range [{clock.show(log.start_ns)}, {clock.show(log.end_ns)}]"
            + offset_hint(log.clock, log.start_ns, start_ns, end_ns)
        )
    return lo, hi


def one_robot(source: LogSource, robots: Sequence[str], what: str) -> Log:
    """The log of the one robot a question over time reads (``robots`` selecting it when the
    log holds several); ``SeveralRobotsError`` otherwise: ``selection.per_robot`` asks the
    question of each robot."""
    log = Selection(tuple(robots)).of(as_log(source))
    if len(log.robots) > 1:
        raise SeveralRobotsError(log.robots, what)
    return log


def timeline(
    source: LogSource,
    *,
    start: TimeArg = None,
    end: TimeArg = None,
    every: bool = False,
    gap_tolerance: float = DEFAULT_GAP_TOLERANCE,
    robots: Sequence[str] = (),
) -> Timeline:
    """A row per decision change (per cycle with ``every``) between ``start`` and ``end``.

    One robot's: ``robots`` selects it in a log of several (``selection.per_robot`` gives
    each robot's timeline). ``WindowOutsideLogError`` when the window misses the log."""
    log = one_robot(source, robots, "decisions in this log")
    require_cycles(log)
    lo, hi = _window(log, start, end)
    runs = log.clock_runs()
    rows: list[TimelineRow] = []
    gaps: list[Gap] = []
    counts: list[tuple[int, int, int | None, int | None]] = []
    for number, run in enumerate(runs):
        found = _rows(
            run,
            lo,
            hi,
            every=every,
            gap_tolerance=gap_tolerance,
            run=number if len(runs) > 1 else None,
        )
        rows.extend(found.rows)
        gaps.extend(found.gaps)
        counts.append((found.cycles, found.changes, found.first_cycle, found.last_cycle))
    clock_runs = (
        tuple(
            ClockRun(tuple(s.path.name for s in run.segments), first, last, n)
            for run, (n, _, first, last) in zip(runs, counts, strict=True)
        )
        if len(runs) > 1
        else ()
    )
    robot = log.first_robot
    return Timeline(
        str(log.root),
        robot,
        lo,
        hi,
        every,
        sum(c[0] for c in counts),
        sum(c[1] for c in counts),
        tuple(rows),
        tuple(gaps),
        log.recovered,
        clock_runs,
        live=log.live or None,
        clock=LogClock.of(log),
        clock_steps=tuple(log.clock_steps()) if len(runs) > 1 else (),
    )


@dataclass(slots=True)
class _RunRows:
    rows: list[TimelineRow]
    gaps: list[Gap]
    cycles: int = 0
    changes: int = 0
    first_cycle: int | None = None
    last_cycle: int | None = None


def _rows(
    log: Log, lo: int, hi: int, *, every: bool, gap_tolerance: float, run: int | None
) -> _RunRows:
    """The rows and gaps of one run of the clock between ``lo`` and ``hi``."""
    period = _period_ns(log)
    gap_of = gap_stepper(log, gap_tolerance)
    out = _RunRows([], [])
    current: TimelineRow | None = None
    for cycle in log.iter_cycles(lo, hi):
        out.cycles += 1
        if out.first_cycle is None:
            out.first_cycle = cycle.cycle
        out.last_cycle = cycle.cycle
        command = command_of(cycle)
        raw_flags, deviation, unit = execution_fields(cycle)
        flags, scenario = split_flags(raw_flags)
        gap = gap_of(cycle)
        if gap is not None:
            out.gaps.append(gap)
        changed = is_decision_change(
            current is not None, None if current is None else current.command, command
        )
        out.changes += changed
        if current is None or every or changed:
            if current is not None:
                current.held_ns = cycle.t_ns - current.t_ns
            decision = read_decision(cycle)
            current = TimelineRow(
                cycle=cycle.cycle,
                t_ns=cycle.t_ns,
                command=command,
                previous=None if current is None else current.command,
                leading=decision.leading,
                rationale=decision.rationale,
                flags=flags,
                end_cycle=cycle.cycle,
                end_t_ns=cycle.t_ns,
                scenario=scenario,
                run=run,
            )
            out.rows.append(current)
        current.cycles += 1
        current.end_cycle, current.end_t_ns = cycle.cycle, cycle.t_ns
        # Only where the writer names the unit (profile 1.1): a number without one cannot
        # be read, and a profile 1.0 record names none.
        if (
            unit is not None
            and deviation is not None
            and (current.max_deviation is None or deviation > current.max_deviation)
        ):
            current.max_deviation, current.deviation_unit = deviation, unit
        if flags:
            current.flagged_cycles += 1
            for flag in flags:
                current.flag_counts[flag] = current.flag_counts.get(flag, 0) + 1
    if current is not None:
        current.held_ns = current.end_t_ns + period - current.t_ns
    return out


# --- why ---------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Transition:
    """A cycle where the command changed to the action asked about, and the reason logged.

    It held for ``held_cycles`` cycles, until ``ended_t_ns`` (the first cycle with another
    command, ``next_command``), or to the end of the log when ``ongoing``. ``held_ns`` runs
    to ``ended_t_ns``, or one period past the last cycle when ongoing.
    """

    cycle: int
    t_ns: int
    command: str
    previous: str | None
    previous_cycle: int | None
    unlogged_before: int
    """Cycles between ``previous_cycle`` and this one that are not in the log (dropped):
    the change may have happened in one of them."""
    rationale: str | None
    truncated: bool
    factors: tuple[FactorValue, ...]
    counterfactuals: tuple[CounterfactualView, ...]
    flags: tuple[str, ...]
    held_cycles: int
    held_ns: int
    last_t_ns: int
    ended_t_ns: int | None
    next_command: str | None
    ongoing: bool

    @property
    def leading(self) -> FactorValue | None:
        return self.factors[0] if self.factors else None


@dataclass(frozen=True, slots=True)
class WhyResult:
    """The transitions into ``action`` (all of them, or the one in force at ``t_ns``)."""

    path: str
    robot: str
    action: str
    t_ns: int | None
    transitions: tuple[Transition, ...]
    actions_present: dict[str, int]
    """Cycles per command in the log (only the action asked about with ``t``)."""
    recovered: bool
    live: bool | None = field(default=None, metadata={OMIT_EMPTY: True})
    """True when a segment of the log is being written right now; left out of JSON else."""
    clock: LogClock = SECONDS_CLOCK
    """The log's clock and first time: how its times are shown (``log_time.LogClock``)."""


def _match(action: str, command: str | None) -> bool:
    return command is not None and command.casefold() == action.casefold()


@dataclass(slots=True)
class _Run:
    """A run of cycles with the action: first and last cycle, the ones around it."""

    first: Cycle
    before: Cycle | None
    last: Cycle
    cycles: int = 1
    after: Cycle | None = None

    def transition(self, period_ns: int) -> Transition:
        decision = read_decision(self.first)
        after = self.after
        end = after.t_ns if after is not None else self.last.t_ns + period_ns
        return Transition(
            cycle=self.first.cycle,
            t_ns=self.first.t_ns,
            command=decision.command or "?",
            previous=None if self.before is None else command_of(self.before),
            previous_cycle=None if self.before is None else self.before.cycle,
            unlogged_before=0
            if self.before is None
            else max(0, self.first.cycle - self.before.cycle - 1),
            rationale=decision.rationale,
            truncated=decision.truncated,
            factors=decision.factors,
            counterfactuals=decision.counterfactuals,
            flags=decision.execution.problems if decision.execution else (),
            held_cycles=self.cycles,
            held_ns=end - self.first.t_ns,
            last_t_ns=self.last.t_ns,
            ended_t_ns=None if after is None else after.t_ns,
            next_command=None if after is None else command_of(after),
            ongoing=after is None,
        )


class ActionNotTakenError(UsageError):
    """The robot never took the asked action (or not by the asked time)."""


def _unknown_action(action: str, present: Counter[str]) -> UsageError:
    listed = ", ".join(f"{c} ({n})" for c, n in present.most_common()) or "none"
    return ActionNotTakenError(
        f"action {action!r} is never taken in this log; actions present: {listed}"
    )


def why(
    source: LogSource, action: str, *, t: TimeArg = None, robots: Sequence[str] = ()
) -> WhyResult:
    """Why the robot took ``action``: each transition into it with its logged reason.

    With ``t``, only the transition that led to the state at ``t`` (the latest one at or
    before ``t``). Without, every transition in the log. The action is matched without
    regard to case. An action the log never shows raises ``ActionNotTakenError`` naming
    those it does. One robot's: ``robots`` selects it in a log of several
    (``selection.per_robot`` asks each robot).
    """
    if not action.strip():
        raise UsageError("--action must name a command, e.g. STOP")
    log = one_robot(source, robots, "decisions in this log")
    require_cycles(log)
    robot = log.first_robot
    period = _period_ns(log)
    clock = LogClock.of(log)
    t_ns = resolve_time(t, log)
    if t_ns is not None:
        log.cycle_at(t_ns)  # raises TimeOutOfRangeError outside the log, naming its range
        run = _run_before(log, action, t_ns)
        if run is None:
            present = Counter(command_of(c) or "?" for c in log.iter_cycles())
            name = next((c for c in present if _match(action, c)), None)
            if name is None:
                raise _unknown_action(action, present)
            first = next(c for c in log.iter_cycles() if _match(action, command_of(c)))
            raise ActionNotTakenError(
                f"{name} is not taken at or before t={clock.show(t_ns)}; it is first taken "
                f"at t={clock.show(first.t_ns)} (cycle {first.cycle})"
            )
        one = run.transition(period)
        return WhyResult(
            str(log.root),
            robot,
            one.command,
            t_ns,
            (one,),
            {one.command: one.held_cycles},
            log.recovered,
            live=log.live or None,
            clock=clock,
        )
    every, present = _all_transitions(log, action, period)
    if not every:
        raise _unknown_action(action, present)
    transitions = tuple(every)
    return WhyResult(
        str(log.root),
        robot,
        transitions[0].command,
        None,
        transitions,
        dict(present.most_common()),
        log.recovered,
        live=log.live or None,
        clock=clock,
    )


def _all_transitions(
    log: Log, action: str, period_ns: int
) -> tuple[list[Transition], Counter[str]]:
    """Every transition into ``action`` in one pass; a run's cycles are let go as it ends."""
    present: Counter[str] = Counter()
    transitions: list[Transition] = []
    current: _Run | None = None
    prev: Cycle | None = None
    for cycle in log.iter_cycles():
        command = command_of(cycle)
        present[command or "?"] += 1
        if _match(action, command):
            if current is None:
                current = _Run(cycle, prev, cycle)
            else:
                current.last = cycle
                current.cycles += 1
        elif current is not None:
            current.after = cycle
            transitions.append(current.transition(period_ns))
            current = None
        prev = cycle
    if current is not None:
        transitions.append(current.transition(period_ns))
    return transitions, present


def _run_before(log: Log, action: str, t_ns: int) -> _Run | None:
    """The latest run of ``action`` that began at or before ``t_ns``, followed to its end."""
    run: _Run | None = None
    for cycle in log.iter_cycles(end_ns=t_ns, reverse=True):
        if _match(action, command_of(cycle)):
            if run is None:
                run = _Run(cycle, None, cycle, cycles=0)
            run.first = cycle
            run.cycles += 1
        elif run is not None:
            run.before = cycle
            break
    if run is None:
        return None
    for cycle in log.iter_cycles(start_ns=run.last.t_ns + 1):
        if not _match(action, command_of(cycle)):
            run.after = cycle
            break
        run.last = cycle
        run.cycles += 1
    return run
