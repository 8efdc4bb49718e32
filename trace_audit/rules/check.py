"""Checking rules over a log: each robot's cycles as signals, judged by rtamt stretch by stretch.

How a rule ``always(body)`` is judged on one robot (docs/rules.md, "Gaps and not decidable"):
the robot's cycles in the window are read in time order (``Selection``, ``each_robot``),
plus as much log before and after as the rules' horizons reach, so that the window's edges
are judged on real cycles. Each cycle's command and signals come straight from its layers
(``signals.read_signals``), its gap from the one gap rule (``log_gaps.gap_stepper``). The
rows are then judged by ``rules.judge``, the one evaluator, which the fleet index's rows go
through too (``rules.index_check``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from trace_audit.log_gaps import gap_stepper
from trace_audit.log_source import LogSource, as_log
from trace_audit.log_time import LogClock, NotWallClockError, TimeArg
from trace_audit.rules.formula import Horizon, RulesError
from trace_audit.rules.judge import RobotSignals, SignalColumns, judge, shows
from trace_audit.rules.results import CheckResult, RobotRules, SeenOutside, Skipped
from trace_audit.rules.rulebook import Rule
from trace_audit.rules.signals import read_signals
from trace_audit.selection import Selection, per_robot
from trace_audit.transitions import WindowOutsideLogError
from trace_runtime.clock import offset_hint
from trace_runtime.errors import TimeOutOfRangeError
from trace_runtime.reading.logset import Log

__all__ = ["check_rules"]


def check_rules(
    source: LogSource,
    rules: Sequence[Rule],
    *,
    robots: Sequence[str] = (),
    start: TimeArg = None,
    end: TimeArg = None,
    rules_file: str = "",
    engine: str = "auto",
) -> CheckResult:
    """Every rule over each selected robot of ``source`` in the window ``start``..``end``;
    ``engine`` as ``Formula.monitor`` takes it (``rtamt``: rtamt's interpreter alone)."""
    if not rules:
        raise RulesError(f"{rules_file or 'the rules'}: no rules to check")
    selection = Selection(tuple(robots), start, end)
    log = selection.of(as_log(source))
    path = str(source) if isinstance(source, str | Path) else str(log.root)
    skipped: list[tuple[str, Exception]] = []
    answers = per_robot(
        log,
        lambda one: _check_robot(one, rules, selection, path, engine),
        skip=(TimeOutOfRangeError, NotWallClockError, WindowOutsideLogError),
        skipped=skipped,
    )
    left_out = tuple(Skipped(robot, str(err)) for robot, err in skipped)
    return CheckResult(path, rules_file, tuple(answers), skipped=left_out)


def _check_robot(
    log: Log, rules: Sequence[Rule], selection: Selection, path: str, engine: str
) -> RobotRules:
    period_ns = log.period_ns
    if period_ns <= 0:
        raise RulesError(f"{log.first_robot}: the log declares no cycle period to judge rules at")
    lo, hi = selection.window(log)
    _overlaps(log, lo, hi)
    judged = judge(_read_rows(log, rules, lo, hi, path), rules, engine=engine)[0]
    unseen = {name for rule in judged.rules for name in rule.unseen}
    if not unseen or (lo is None and hi is None):
        return judged
    outside = _seen_outside(log, sorted(unseen), lo, hi)
    return replace(
        judged,
        rules=tuple(
            replace(rule, seen_outside=tuple(outside[n] for n in rule.unseen if n in outside))
            for rule in judged.rules
        ),
    )


def _seen_outside(
    log: Log, names: list[str], lo: int | None, hi: int | None
) -> dict[str, SeenOutside]:
    """Where the robot's log, outside the window ``lo``..``hi``, shows each of ``names``
    (none of which the window shows): read only when a window hides a signal, so that a
    note calls a name a typo only when the whole log never shows it."""
    import numpy as np

    found: dict[str, SeenOutside] = {}
    for cycle in log.iter_cycles():
        if (lo is None or cycle.t_ns >= lo) and (hi is None or cycle.t_ns <= hi):
            continue
        values = read_signals(cycle, names)[1]
        for name, value in values.items():
            if not shows(name, np.array([value])):
                continue
            first = found.get(name)
            found[name] = SeenOutside(
                name,
                cycle.t_ns if first is None else first.first_ns,
                cycle.t_ns,
                cycle.cycle if first is None else first.first_cycle,
                cycle.cycle,
            )
    return found


def _overlaps(log: Log, lo: int | None, hi: int | None) -> None:
    """``WindowOutsideLogError`` (exit 2, naming the log's range, as ``trace-audit timeline``
    does) when the window ``lo``..``hi`` holds none of the robot's log time."""
    clock = LogClock.of(log)
    first, last = log.start_ns, log.end_ns
    start = first if lo is None else lo
    end = last if hi is None else hi
    shown = f"[{clock.show(start)}, {clock.show(end)}]"
    where = f"the log's range [{clock.show(first)}, {clock.show(last)}]"
    if lo is not None and hi is not None and hi < lo:
        raise WindowOutsideLogError(f"the window {shown} ends before it starts ({where})")
    if start > last or end < first or end < start:
        hint = offset_hint(log.clock, first, lo, hi)
        raise WindowOutsideLogError(f"the window {shown} does not overlap {where}{hint}")


def _read_rows(
    log: Log, rules: Sequence[Rule], lo: int | None, hi: int | None, path: str
) -> RobotSignals:
    """The robot's cycles in the window and the context the widest horizon needs."""
    horizon = Horizon()
    for rule in rules:
        horizon = horizon.widest(rule.formula.horizon)
    past_ns, future_ns = horizon.span_ns(log.period_ns)
    names = tuple(dict.fromkeys(s for rule in rules for s in rule.formula.signals))
    step = gap_stepper(log)
    rows = SignalColumns(names)
    read_lo = None if lo is None else lo - past_ns
    read_hi = None if hi is None else hi + future_ns
    for cycle in log.iter_cycles(read_lo, read_hi):
        gap = step(cycle)
        command, signals = read_signals(cycle, names)
        judged = (lo is None or cycle.t_ns >= lo) and (hi is None or cycle.t_ns <= hi)
        rows.add(cycle.cycle, cycle.t_ns, command, signals, gap, judged)
    return rows.build(log.first_robot, log.period_ns, LogClock.of(log), path)
