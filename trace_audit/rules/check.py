"""Checking rules over a log: each robot's cycles as signals, judged by rtamt stretch by stretch.

How a rule ``always(body)`` is judged on one robot (docs/rules.md, "Gaps and not decidable"):

1. The robot's cycles in the window are read in time order (``Selection``, ``each_robot``),
   plus as much log before and after as the rules' horizons reach, so that the window's
   edges are judged on real cycles. Each cycle's signals come from its ``Decision``
   (``read_decision``) and its perception (``signals.read_signals``).
2. The cycles are cut into *stretches*: a gap between two sealed cycles (the one gap rule,
   ``log_gaps.gap_stepper``) ends a stretch, and so does a cycle that does not log a signal
   the rule reads (it is judged nowhere). Nothing is interpolated.
3. rtamt evaluates the body over each stretch separately, in discrete time: the i-th cycle of
   the stretch is step i, at the log's period (``Formula.evaluate``).
4. A cycle is *decidable* when its horizon (past ``p`` and future ``f`` cycles,
   ``Formula.horizon``) stays inside its stretch: at least ``p`` cycles before it and ``f``
   after it. Only decidable cycles are judged; rtamt's value at the others (read over a
   truncated stretch) is never used.
5. The rule's robustness is the lowest body robustness over the decidable cycles of the
   window (``always``'s robustness); each run of decidable cycles below 0 is a
   ``Violation``; the cycles that cannot be judged, and every gap in the window, are
   ``Undecided`` stretches naming the gap, the missing signal, or the log's end.
"""

from __future__ import annotations

import shlex
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from trace_audit.causal import read_decision
from trace_audit.log_gaps import gap_stepper
from trace_audit.log_source import LogSource, as_log
from trace_audit.log_time import LogClock, NotWallClockError, TimeArg
from trace_audit.rules.formula import Formula, Horizon, RulesError
from trace_audit.rules.results import (
    CheckResult,
    Outcome,
    RobotRules,
    RuleResult,
    Undecided,
    UndecidedReason,
    Violation,
)
from trace_audit.rules.rulebook import Rule
from trace_audit.rules.signals import read_signals
from trace_audit.selection import Selection, per_robot
from trace_runtime.errors import TimeOutOfRangeError
from trace_runtime.gaps import Gap
from trace_runtime.logset import Log

__all__ = ["check_rules"]


@dataclass(frozen=True, slots=True)
class _Row:
    """One logged cycle as the rules read it."""

    cycle: int
    t_ns: int
    command: str | None
    signals: dict[str, float]
    gap_before: Gap | None
    judged: bool
    """Inside the window (the cycles read around it only give context)."""


def check_rules(
    source: LogSource,
    rules: Sequence[Rule],
    *,
    robots: Sequence[str] = (),
    start: TimeArg = None,
    end: TimeArg = None,
    rules_file: str = "",
) -> CheckResult:
    """Every rule over each selected robot of ``source`` in the window ``start``..``end``."""
    if not rules:
        raise RulesError(f"{rules_file or 'the rules'}: no rules to check")
    selection = Selection(tuple(robots), start, end)
    log = selection.of(as_log(source))
    path = str(source) if isinstance(source, str | Path) else str(log.root)
    answers = per_robot(
        log,
        lambda one: _check_robot(one, rules, selection, path),
        skip=(TimeOutOfRangeError, NotWallClockError),
    )
    return CheckResult(path, rules_file, tuple(answers))


def _check_robot(log: Log, rules: Sequence[Rule], selection: Selection, path: str) -> RobotRules:
    period_ns = log.period_ns
    if period_ns <= 0:
        raise RulesError(f"{log.first_robot}: the log declares no cycle period to judge rules at")
    lo, hi = selection.window(log)
    rows = _read_rows(log, rules, lo, hi)
    clock = LogClock.of(log)
    results = tuple(
        _judge(rule.formula, rows, period_ns, clock, log=log, path=path) for rule in rules
    )
    judged = sum(1 for r in rows if r.judged)
    return RobotRules(log.first_robot, period_ns, judged, results, clock)


def _read_rows(log: Log, rules: Sequence[Rule], lo: int | None, hi: int | None) -> list[_Row]:
    """The robot's cycles in the window and the context the widest horizon needs."""
    horizon = Horizon()
    for rule in rules:
        horizon = horizon.widest(rule.formula.horizon)
    past_ns, future_ns = horizon.span_ns(log.period_ns)
    names = tuple(dict.fromkeys(s for rule in rules for s in rule.formula.signals))
    step = gap_stepper(log)
    rows: list[_Row] = []
    read_lo = None if lo is None else lo - past_ns
    read_hi = None if hi is None else hi + future_ns
    for cycle in log.iter_cycles(read_lo, read_hi):
        gap = step(cycle)
        decision = read_decision(cycle)
        rows.append(
            _Row(
                cycle.cycle,
                cycle.t_ns,
                decision.command,
                read_signals(cycle, decision, names),
                gap,
                (lo is None or cycle.t_ns >= lo) and (hi is None or cycle.t_ns <= hi),
            )
        )
    return rows


# --- one rule --------------------------------------------------------------------------------


@dataclass(slots=True)
class _Verdict:
    """One row's verdict for a rule: its robustness when decidable, else why not."""

    robustness: float | None
    reason: UndecidedReason | None = None
    detail: str = ""
    gap: Gap | None = None


def _judge(
    formula: Formula, rows: list[_Row], period_ns: int, clock: LogClock, *, log: Log, path: str
) -> RuleResult:
    verdicts = _verdicts(formula, rows, period_ns)
    judged = [(row, v) for row, v in zip(rows, verdicts, strict=True) if row.judged]
    decidable = [v.robustness for _, v in judged if v.robustness is not None]
    violations = _violations(rows, verdicts, clock, log.first_robot, path)
    undecided = _undecided(rows, verdicts, clock)
    if violations:
        outcome = Outcome.VIOLATED
    elif not decidable or any(
        u.reason in (UndecidedReason.GAP, UndecidedReason.MISSING_SIGNAL) for u in undecided
    ):
        outcome = Outcome.NOT_DECIDABLE
    else:
        outcome = Outcome.SATISFIED
    return RuleResult(
        formula.rule,
        formula.stl,
        outcome,
        min(decidable) if decidable else None,
        len(decidable),
        violations,
        undecided,
    )


def _verdicts(formula: Formula, rows: list[_Row], period_ns: int) -> list[_Verdict]:
    """Each row's verdict: rtamt over each stretch, decidable rows only."""
    past, future = formula.horizon.steps(period_ns)
    out: list[_Verdict] = []
    for start, stop in _stretches(formula, rows):
        if start == stop:  # a row without a signal the rule reads
            missing = next(s for s in formula.signals if s not in rows[start].signals)
            out.append(_Verdict(None, UndecidedReason.MISSING_SIGNAL, f"{missing} not logged"))
            continue
        stretch = rows[start:stop]
        columns = {s: [r.signals[s] for r in stretch] for s in formula.signals}
        robustness = formula.evaluate(columns, period_ns)
        before = _boundary(rows, start, before=True)
        after = _boundary(rows, stop - 1, before=False)
        for i, value in enumerate(robustness):
            if i < past:
                out.append(_Verdict(None, *before))
            elif i >= len(stretch) - future:
                out.append(_Verdict(None, *after))
            else:
                out.append(_Verdict(value))
    return out


def _stretches(formula: Formula, rows: list[_Row]) -> list[tuple[int, int]]:
    """Row ranges ``[start, stop)`` of the stretches; a row missing a signal is its own
    empty range ``(i, i)``."""
    out: list[tuple[int, int]] = []
    start = 0
    for i, row in enumerate(rows):
        complete = all(s in row.signals for s in formula.signals)
        if row.gap_before is not None or not complete:
            if start < i:
                out.append((start, i))
            start = i
        if not complete:
            out.append((i, i))
            start = i + 1
    if start < len(rows):
        out.append((start, len(rows)))
    return out


def _boundary(rows: list[_Row], i: int, *, before: bool) -> tuple[UndecidedReason, str, Gap | None]:
    """What ends the stretch at row ``i``, on the side asked: a gap, a row without a signal,
    or the end of what the log holds."""
    if before:
        gap = rows[i].gap_before
        if gap is not None:
            return UndecidedReason.GAP, _gap_detail(gap), gap
        if i == 0:
            return UndecidedReason.LOG_START, "the horizon reaches before the log's start", None
        return UndecidedReason.MISSING_SIGNAL, f"cycle {rows[i - 1].cycle} lacks a signal", None
    if i + 1 == len(rows):
        return UndecidedReason.LOG_END, "the horizon reaches past the log's end", None
    gap = rows[i + 1].gap_before
    if gap is not None:
        return UndecidedReason.GAP, _gap_detail(gap), gap
    return UndecidedReason.MISSING_SIGNAL, f"cycle {rows[i + 1].cycle} lacks a signal", None


def _gap_detail(gap: Gap) -> str:
    n = gap.missing_cycles
    return (
        f"gap after cycle {gap.after_cycle}: {n} cycle{'s' if n != 1 else ''} "
        f"({gap.gap_ns / 1e9:.3f} s) not logged"
    )


def _violations(
    rows: list[_Row], verdicts: list[_Verdict], clock: LogClock, robot: str, path: str
) -> tuple[Violation, ...]:
    """Runs of consecutive judged rows (no gap between) with negative robustness."""
    runs: list[list[int]] = []
    for i, (row, v) in enumerate(zip(rows, verdicts, strict=True)):
        bad = row.judged and v.robustness is not None and v.robustness < 0
        if not bad:
            continue
        if runs and runs[-1][-1] == i - 1 and row.gap_before is None:
            runs[-1].append(i)
        else:
            runs.append([i])
    out: list[Violation] = []
    for run in runs:
        first, last = rows[run[0]], rows[run[-1]]
        lowest = min(verdicts[i].robustness or 0.0 for i in run)
        explain = (
            f"trace-audit explain {shlex.quote(path)} --cycle {first.cycle} "
            f"--robot {shlex.quote(robot)}"
        )
        out.append(
            Violation(
                robot,
                first.t_ns,
                last.t_ns,
                clock.arg(first.t_ns),
                clock.arg(last.t_ns),
                first.cycle,
                last.cycle,
                len(run),
                lowest,
                first.command,
                explain,
            )
        )
    return tuple(out)


def _undecided(
    rows: list[_Row], verdicts: list[_Verdict], clock: LogClock
) -> tuple[Undecided, ...]:
    """Stretches of judged rows that cannot be judged, joined with the gap they touch; every
    gap inside the window is one (its cycles were never logged)."""
    groups: list[tuple[_Verdict, list[int]]] = []
    for i, (row, v) in enumerate(zip(rows, verdicts, strict=True)):
        gap = row.gap_before if (row.judged or (i and rows[i - 1].judged)) else None
        if gap is not None and not (groups and groups[-1][0].gap is gap):
            groups.append((_Verdict(None, UndecidedReason.GAP, _gap_detail(gap), gap), []))
        if not row.judged or v.reason is None:
            continue
        last = groups[-1] if groups else None
        if (
            last is not None
            and (not last[1] or last[1][-1] == i - 1)
            and last[0].reason == v.reason
            and last[0].gap is v.gap
        ):
            last[1].append(i)
        else:
            groups.append((v, [i]))
    return tuple(_stretch(rows, v, members, clock) for v, members in groups)


def _stretch(rows: list[_Row], v: _Verdict, members: list[int], clock: LogClock) -> Undecided:
    times = [rows[i].t_ns for i in members]
    cycles = [rows[i].cycle for i in members]
    gap = v.gap
    if gap is not None:  # the gap's own, unlogged, cycles belong to the stretch
        times += [gap.after_t_ns + gap.period_ns, gap.before_t_ns - gap.period_ns]
        cycles += [gap.after_cycle + 1, gap.before_cycle - 1]
    assert v.reason is not None
    return Undecided(
        v.reason,
        v.detail,
        min(times),
        max(times),
        clock.arg(min(times)),
        clock.arg(max(times)),
        min(cycles),
        max(cycles),
        len(members),
        gap,
    )
