"""Judging rules over one robot's signal rows: rtamt stretch by stretch, gaps never bridged.

The one evaluator of ``check``, whatever the signals were read from: a log's cycles
(``trace_audit.rules.check``) or the fleet index's rows (``trace_audit.rules.index_check``).
Each source gives a robot's ``RobotSignals``: its rows in time order (each with its signal
values, the gap that ends before it, whether it is inside the window, the path its
``explain`` command names and its group, e.g. the index's day), the sampling period, the
clock, and the signals it cannot give at all. docs/rules.md, "Gaps and not decidable":

1. The rows are cut into *stretches*: a gap between two sealed cycles (the one gap rule)
   ends a stretch, and so does a row that does not hold a signal the rule reads (it is
   judged nowhere). Nothing is interpolated.
2. rtamt evaluates the body over each stretch separately, in discrete time: the i-th row of
   the stretch is step i, at the log's period (``Formula.evaluate``).
3. A row is *decidable* when its horizon (past ``p`` and future ``f`` cycles,
   ``Formula.horizon``) stays inside its stretch. Only decidable rows are judged; rtamt's
   value at the others (read over a truncated stretch) is never used.
4. The rule's robustness is the lowest body robustness over the decidable rows of the
   window; each run of decidable rows below 0 is a ``Violation``; the rows that cannot be
   judged, and every gap in the window, are ``Undecided`` stretches naming the gap, the
   missing signal, or the log's end.
"""

from __future__ import annotations

import shlex
from collections.abc import Sequence
from dataclasses import dataclass

from trace_audit.log_time import LogClock
from trace_audit.rules.formula import Formula
from trace_audit.rules.results import (
    GroupRule,
    GroupRules,
    Outcome,
    RobotRules,
    RuleResult,
    Undecided,
    UndecidedReason,
    Violation,
)
from trace_audit.rules.rulebook import Rule
from trace_runtime.gaps import Gap

__all__ = ["RobotSignals", "SignalRow", "judge_groups", "judge_robot"]


@dataclass(frozen=True, slots=True)
class SignalRow:
    """One logged cycle as the rules read it."""

    cycle: int
    t_ns: int
    command: str | None
    signals: dict[str, float]
    gap_before: Gap | None
    judged: bool
    """Inside the window (the cycles read around it only give context)."""
    source: str
    """The path ``trace-audit explain`` reads this cycle from."""
    group: str = ""
    """The group a ``--by`` table puts the row in (the index's ``day``)."""


@dataclass(frozen=True, slots=True)
class RobotSignals:
    """One robot's rows, in time order, and what judging them needs."""

    robot: str
    period_ns: int
    clock: LogClock
    rows: list[SignalRow]


@dataclass(slots=True)
class _Verdict:
    """One row's verdict for a rule: its robustness when decidable, else why not."""

    robustness: float | None
    reason: UndecidedReason | None = None
    detail: str = ""
    gap: Gap | None = None


def judge_robot(signals: RobotSignals, rules: Sequence[Rule]) -> RobotRules:
    """Every rule over one robot's rows."""
    judged = [r.judged for r in signals.rows]
    results = tuple(
        _result(rule.formula, signals, _verdicts(rule.formula, signals), judged) for rule in rules
    )
    return RobotRules(signals.robot, signals.period_ns, sum(judged), results, signals.clock)


def judge_groups(signals: RobotSignals, rules: Sequence[Rule]) -> tuple[GroupRules, ...]:
    """Every rule over each group of one robot's judged rows (in order of first row): the
    same verdicts as ``judge_robot``, summed within the group."""
    groups = list(dict.fromkeys(r.group for r in signals.rows if r.judged))
    verdicts = [_verdicts(rule.formula, signals) for rule in rules]
    out: list[GroupRules] = []
    for group in groups:
        mask = [r.judged and r.group == group for r in signals.rows]
        results = tuple(
            GroupRule.of(_result(rule.formula, signals, v, mask))
            for rule, v in zip(rules, verdicts, strict=True)
        )
        out.append(GroupRules(signals.robot, group, sum(mask), results))
    return tuple(out)


def _result(
    formula: Formula, signals: RobotSignals, verdicts: list[_Verdict], judged: list[bool]
) -> RuleResult:
    rows = signals.rows
    decidable = [
        v.robustness
        for v, j in zip(verdicts, judged, strict=True)
        if j and v.robustness is not None
    ]
    violations = _violations(rows, verdicts, judged, signals.clock, signals.robot)
    undecided = _undecided(rows, verdicts, judged, signals.clock)
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


def _verdicts(formula: Formula, signals: RobotSignals) -> list[_Verdict]:
    """Each row's verdict: rtamt over each stretch, decidable rows only."""
    rows, period_ns = signals.rows, signals.period_ns
    past, future = formula.horizon.steps(period_ns)
    out: list[_Verdict] = []
    monitor = None
    for start, stop in _stretches(formula, rows):
        if start == stop:  # a row without a signal the rule reads
            missing = next(s for s in formula.signals if s not in rows[start].signals)
            out.append(_Verdict(None, UndecidedReason.MISSING_SIGNAL, f"{missing} not logged"))
            continue
        stretch = rows[start:stop]
        columns = {s: [r.signals[s] for r in stretch] for s in formula.signals}
        if monitor is None:
            monitor = formula.monitor(period_ns)
        robustness = monitor(columns)
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


def _stretches(formula: Formula, rows: list[SignalRow]) -> list[tuple[int, int]]:
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


def _boundary(
    rows: list[SignalRow], i: int, *, before: bool
) -> tuple[UndecidedReason, str, Gap | None]:
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
    rows: list[SignalRow],
    verdicts: list[_Verdict],
    judged: list[bool],
    clock: LogClock,
    robot: str,
) -> tuple[Violation, ...]:
    """Runs of consecutive judged rows (no gap between) with negative robustness."""
    runs: list[list[int]] = []
    for i, (row, v) in enumerate(zip(rows, verdicts, strict=True)):
        bad = judged[i] and v.robustness is not None and v.robustness < 0
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
            f"trace-audit explain {shlex.quote(first.source)} --cycle {first.cycle} "
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
    rows: list[SignalRow], verdicts: list[_Verdict], judged: list[bool], clock: LogClock
) -> tuple[Undecided, ...]:
    """Stretches of judged rows that cannot be judged, joined with the gap they touch; every
    gap inside the window is one (its cycles were never logged)."""
    groups: list[tuple[_Verdict, list[int]]] = []
    for i, (row, v) in enumerate(zip(rows, verdicts, strict=True)):
        gap = row.gap_before if (judged[i] or (i and judged[i - 1])) else None
        if gap is not None and not (groups and groups[-1][0].gap is gap):
            groups.append((_Verdict(None, UndecidedReason.GAP, _gap_detail(gap), gap), []))
        if not judged[i] or v.reason is None:
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


def _stretch(rows: list[SignalRow], v: _Verdict, members: list[int], clock: LogClock) -> Undecided:
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
