"""Judging rules over one robot's signal rows: rtamt stretch by stretch, gaps never bridged.

The one evaluator of ``check``, whatever the signals were read from: a log's cycles
(``trace_audit.rules.check``) or the fleet index's rows (``trace_audit.rules.index_check``).
Each source gives a robot's ``RobotSignals``: its rows in time order as columns (cycle,
time, command, each signal's values with NaN where the row does not log it, whether the
row is inside the window, the path its ``explain`` command names and its group, e.g. the
index's day), the gaps by the row each ends before, the sampling period and the clock.
Rows are columns, not objects, so that a fleet's days of cycles are judged in numpy; only
what is reported (violations, undecided stretches) becomes objects. docs/rules.md, "Gaps
and not decidable":

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
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

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
from trace_audit.rules.signals import is_indicator
from trace_runtime.gaps import Gap

__all__ = ["Labels", "RobotSignals", "SignalColumns", "judge", "shows"]


@dataclass(frozen=True, slots=True)
class Labels:
    """A text column as codes into its distinct values (a fleet's days of rows without a
    Python string a row): row ``i`` reads ``names[codes[i]]``."""

    codes: NDArray[np.int64]
    names: tuple[str | None, ...]

    def __getitem__(self, row: int) -> str | None:
        return self.names[int(self.codes[row])]

    @classmethod
    def of(cls, values: Sequence[str | None]) -> Labels:
        index: dict[str | None, int] = {}
        codes = [index.setdefault(v, len(index)) for v in values]
        return cls(np.array(codes, dtype=np.int64), tuple(index))

    @classmethod
    def same(cls, value: str, n: int) -> Labels:
        return cls(np.zeros(n, dtype=np.int64), (value,))


@dataclass(frozen=True, slots=True)
class RobotSignals:
    """One robot's rows, in time order, as columns, and what judging them needs."""

    robot: str
    period_ns: int
    clock: LogClock
    cycles: NDArray[np.int64]
    t_ns: NDArray[np.int64]
    commands: Labels
    """The decision in force at each row (None: no action logged)."""
    values: Mapping[str, NDArray[np.float64]]
    """Signal name -> its value at each row, NaN where the row does not log it; a signal
    no row logs may be absent."""
    judged: NDArray[np.bool_]
    """Inside the window (the rows read around it only give context)."""
    sources: Labels
    """The path ``trace-audit explain`` reads each row from."""
    gaps: Mapping[int, Gap] = field(default_factory=dict)
    """Row -> the gap that ends before it."""
    groups: Labels | None = None
    """The group a ``--by`` table puts each row in (the index's ``day``); None: none."""

    def __len__(self) -> int:
        return len(self.cycles)

    def column(self, name: str) -> NDArray[np.float64]:
        """A signal's values (all NaN when no row logs it)."""
        values = self.values.get(name)
        return np.full(len(self), np.nan) if values is None else values


class SignalColumns:
    """``RobotSignals`` built one row at a time (a log's cycles, read in order)."""

    def __init__(self, names: Sequence[str]) -> None:
        self.names = tuple(names)
        self.cycles: list[int] = []
        self.t_ns: list[int] = []
        self.commands: list[str | None] = []
        self.values: dict[str, list[float]] = {name: [] for name in self.names}
        self.judged: list[bool] = []
        self.gaps: dict[int, Gap] = {}

    def add(  # noqa: PLR0917 - one row's columns, in the order RobotSignals keeps them
        self,
        cycle: int,
        t_ns: int,
        command: str | None,
        signals: Mapping[str, float],
        gap_before: Gap | None,
        judged: bool,
    ) -> None:
        if gap_before is not None:
            self.gaps[len(self.cycles)] = gap_before
        self.cycles.append(cycle)
        self.t_ns.append(t_ns)
        self.commands.append(command)
        for name, column in self.values.items():
            column.append(signals.get(name, np.nan))
        self.judged.append(judged)

    def build(self, robot: str, period_ns: int, clock: LogClock, source: str) -> RobotSignals:
        n = len(self.cycles)
        return RobotSignals(
            robot,
            period_ns,
            clock,
            np.array(self.cycles, dtype=np.int64),
            np.array(self.t_ns, dtype=np.int64),
            Labels.of(self.commands),
            {name: np.array(v, dtype=np.float64) for name, v in self.values.items()},
            np.array(self.judged, dtype=np.bool_),
            Labels.same(source, n),
            self.gaps,
        )


@dataclass(frozen=True, slots=True)
class _Verdict:
    """Why rows cannot be judged: the reason, its detail, and the gap it touches."""

    reason: UndecidedReason
    detail: str = ""
    gap: Gap | None = None


@dataclass(frozen=True, slots=True)
class _Verdicts:
    """Each row's verdict for one rule: its robustness where ``kind`` is -1 (decidable),
    else ``kinds[kind]`` says why not."""

    robustness: NDArray[np.float64]
    kind: NDArray[np.int32]
    kinds: list[_Verdict]


def judge(
    signals: RobotSignals, rules: Sequence[Rule], *, by_group: bool = False, engine: str = "auto"
) -> tuple[RobotRules, tuple[GroupRules, ...]]:
    """Every rule over one robot's rows, and (``by_group``) over each group of its judged
    rows in order of first row: the same verdicts, summed within the group. ``engine`` as
    ``Formula.monitor`` takes it."""
    verdicts = [_verdicts(rule.formula, signals, engine) for rule in rules]
    judged = signals.judged
    results = tuple(
        _result(rule.formula, signals, v, judged) for rule, v in zip(rules, verdicts, strict=True)
    )
    robot = RobotRules(signals.robot, signals.period_ns, int(judged.sum()), results, signals.clock)
    return robot, _groups(signals, rules, verdicts) if by_group else ()


def _groups(
    signals: RobotSignals, rules: Sequence[Rule], verdicts: list[_Verdicts]
) -> tuple[GroupRules, ...]:
    if signals.groups is None:
        return ()
    codes, judged = signals.groups.codes, signals.judged
    present, first = np.unique(codes[judged], return_index=True)
    out: list[GroupRules] = []
    for code in present[np.argsort(first)].tolist():  # in order of first row
        mask = judged & (codes == code)
        results = tuple(
            GroupRule.of(_result(rule.formula, signals, v, mask))
            for rule, v in zip(rules, verdicts, strict=True)
        )
        group = signals.groups.names[code]
        out.append(GroupRules(signals.robot, str(group), int(mask.sum()), results))
    return tuple(out)


def _result(
    formula: Formula, signals: RobotSignals, verdicts: _Verdicts, judged: NDArray[np.bool_]
) -> RuleResult:
    decidable_rows = judged & (verdicts.kind < 0)
    decidable = verdicts.robustness[decidable_rows]
    violations = _violations(signals, verdicts, decidable_rows)
    undecided = _undecided(signals, verdicts, judged)
    if violations:
        outcome = Outcome.VIOLATED
    elif not len(decidable) or any(
        u.reason in (UndecidedReason.GAP, UndecidedReason.MISSING_SIGNAL) for u in undecided
    ):
        outcome = Outcome.NOT_DECIDABLE
    else:
        outcome = Outcome.SATISFIED
    return RuleResult(
        formula.rule,
        formula.stl,
        outcome,
        _lowest(decidable),
        len(decidable),
        violations,
        undecided,
        _unseen(formula, signals, judged),
    )


def _unseen(formula: Formula, signals: RobotSignals, judged: NDArray[np.bool_]) -> tuple[str, ...]:
    """The rule's signals the judged rows never show (``RuleResult.unseen``)."""
    out: list[str] = []
    if not judged.any():
        return ()
    for name in formula.signals:
        if not shows(name, signals.column(name)[judged]):
            out.append(name)
    return tuple(out)


def shows(name: str, values: NDArray[np.float64]) -> bool:
    """Whether rows with these ``values`` of signal ``name`` show it: a class perceived
    (a finite ``nearest.*``), an indicator at 1 (a command in force, a flag raised), any
    other signal logged (not NaN)."""
    if name.partition(".")[0] == "nearest":
        return bool(np.isfinite(values).any())
    if is_indicator(name):
        return bool((values == 1.0).any())
    return not bool(np.isnan(values).all())


def _lowest(values: NDArray[np.float64]) -> float | None:
    if not len(values):
        return None
    if np.isnan(values).any():  # as Python's min over the rows in order would answer
        return float(min(values.tolist()))
    return float(values.min())


def _verdicts(formula: Formula, signals: RobotSignals, engine: str) -> _Verdicts:
    """Each row's verdict: rtamt's semantics over each stretch, decidable rows only."""
    n = len(signals)
    past, future = formula.horizon.steps(signals.period_ns)
    robustness = np.full(n, np.nan)
    kind = np.full(n, -1, dtype=np.int32)
    kinds: list[_Verdict] = []
    columns = {s: signals.column(s) for s in formula.signals}
    missing = np.zeros(n, dtype=np.bool_)
    for values in columns.values():
        missing |= np.isnan(values)
    monitor = None
    for start, stop in _stretches(signals, missing):
        if start == stop:  # a row without a signal the rule reads
            lacking = next(s for s in formula.signals if np.isnan(columns[s][start]))
            kind[start] = len(kinds)
            kinds.append(_Verdict(UndecidedReason.MISSING_SIGNAL, f"{lacking} not logged"))
            continue
        if monitor is None:
            monitor = formula.monitor(signals.period_ns, engine=engine)
        robustness[start:stop] = monitor({s: v[start:stop] for s, v in columns.items()})
        length = stop - start
        head = min(past, length)
        if head:
            kind[start : start + head] = len(kinds)
            kinds.append(_boundary(signals, missing, start, before=True))
        tail = min(future, length)
        if tail:
            kind[max(stop - tail, start + head) : stop] = len(kinds)
            kinds.append(_boundary(signals, missing, stop - 1, before=False))
    return _Verdicts(robustness, kind, kinds)


def _stretches(signals: RobotSignals, missing: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Row ranges ``[start, stop)`` of the stretches, in order; a row missing a signal is
    its own empty range ``(i, i)``."""
    n = len(signals)
    cuts = set(signals.gaps)
    lacking = np.flatnonzero(missing).tolist()
    cuts.update(lacking)
    cuts.update(i + 1 for i in lacking)
    out: list[tuple[int, int]] = []
    lacks = set(lacking)
    start = 0
    for cut in sorted(c for c in cuts if 0 < c <= n):
        if start < cut:
            out.append((start, cut) if start not in lacks else (start, start))
        start = cut
    if start < n:
        out.append((start, n) if start not in lacks else (start, start))
    return out


def _boundary(
    signals: RobotSignals, missing: NDArray[np.bool_], i: int, *, before: bool
) -> _Verdict:
    """What ends the stretch at row ``i``, on the side asked: a gap, a row without a signal,
    or the end of what the log holds."""
    if before:
        gap = signals.gaps.get(i)
        if gap is not None:
            return _Verdict(UndecidedReason.GAP, _gap_detail(gap), gap)
        if i == 0:
            return _Verdict(UndecidedReason.LOG_START, "the horizon reaches before the log's start")
        cycle = int(signals.cycles[i - 1])
        return _Verdict(UndecidedReason.MISSING_SIGNAL, f"cycle {cycle} lacks a signal")
    if i + 1 == len(signals):
        return _Verdict(UndecidedReason.LOG_END, "the horizon reaches past the log's end")
    gap = signals.gaps.get(i + 1)
    if gap is not None:
        return _Verdict(UndecidedReason.GAP, _gap_detail(gap), gap)
    cycle = int(signals.cycles[i + 1])
    return _Verdict(UndecidedReason.MISSING_SIGNAL, f"cycle {cycle} lacks a signal")


def _gap_detail(gap: Gap) -> str:
    n = gap.missing_cycles
    return (
        f"gap after cycle {gap.after_cycle}: {n} cycle{'s' if n != 1 else ''} "
        f"({gap.gap_ns / 1e9:.3f} s) not logged"
    )


def _violations(
    signals: RobotSignals, verdicts: _Verdicts, decidable: NDArray[np.bool_]
) -> tuple[Violation, ...]:
    """Runs of consecutive judged rows (no gap between) with negative robustness."""
    bad = np.flatnonzero(decidable & (verdicts.robustness < 0))
    if not len(bad):
        return ()
    gaps = signals.gaps
    breaks = [k for k in range(1, len(bad)) if bad[k] != bad[k - 1] + 1 or int(bad[k]) in gaps]
    out: list[Violation] = []
    robot, clock = signals.robot, signals.clock
    for lo, hi in zip([0, *breaks], [*breaks, len(bad)], strict=True):
        first, last = int(bad[lo]), int(bad[hi - 1])
        source, cycle = str(signals.sources[first]), int(signals.cycles[first])
        explain = (
            f"trace-audit explain {shlex.quote(source)} --cycle {cycle} "
            f"--robot {shlex.quote(robot)}"
        )
        first_ns, last_ns = int(signals.t_ns[first]), int(signals.t_ns[last])
        out.append(
            Violation(
                robot,
                first_ns,
                last_ns,
                clock.arg(first_ns),
                clock.arg(last_ns),
                cycle,
                int(signals.cycles[last]),
                hi - lo,
                float(verdicts.robustness[bad[lo:hi]].min()),
                signals.commands[first],
                explain,
            )
        )
    return tuple(out)


def _undecided(
    signals: RobotSignals, verdicts: _Verdicts, judged: NDArray[np.bool_]
) -> tuple[Undecided, ...]:
    """Stretches of judged rows that cannot be judged, joined with the gap they touch; every
    gap inside the window is one (its cycles were never logged)."""
    n = len(signals)
    kind = verdicts.kind
    rows = set(np.flatnonzero(judged & (kind >= 0)).tolist())
    rows.update(i for i in signals.gaps if i < n)
    groups: list[tuple[_Verdict, list[int]]] = []
    for i in sorted(rows):
        gap_before = signals.gaps.get(i)
        gap = gap_before if (judged[i] or (i and judged[i - 1])) else None
        if gap is not None and not (groups and groups[-1][0].gap is gap):
            groups.append((_Verdict(UndecidedReason.GAP, _gap_detail(gap), gap), []))
        if not judged[i] or kind[i] < 0:
            continue
        v = verdicts.kinds[kind[i]]
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
    return tuple(_stretch(signals, v, members) for v, members in groups)


def _stretch(signals: RobotSignals, v: _Verdict, members: list[int]) -> Undecided:
    times = signals.t_ns[members].tolist() if members else []
    cycles = signals.cycles[members].tolist() if members else []
    gap = v.gap
    if gap is not None:  # the gap's own, unlogged, cycles belong to the stretch
        times += [gap.after_t_ns + gap.period_ns, gap.before_t_ns - gap.period_ns]
        cycles += [gap.after_cycle + 1, gap.before_cycle - 1]
    clock = signals.clock
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
