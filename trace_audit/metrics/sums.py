"""The running sums a scan adds decisions into, and what it hands to a decision sink.

``GroupSums`` are merged by addition across segments and processes (and rebuilt from the
fleet index's decision rows); ``ScanResult`` is everything scanning some segments produced,
merged in plan order so the listed failures are the same in every run.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

from trace_audit.chains import DecisionScore
from trace_audit.metrics.results import DecisionFailure
from trace_runtime.costs import CostHistogram
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.gaps import Gap
from trace_runtime.reading.reader import Segment

__all__ = [
    "HAS_CHANNELS",
    "MAY_FAIL_A_CHECK",
    "CheckTally",
    "DecisionSink",
    "GroupSums",
    "ScanResult",
    "ScoredDecision",
    "SealOutcome",
    "add_channels",
    "add_failed_checks",
    "failed_check_rules",
]


@dataclass(slots=True)
class GroupSums:
    """Running sums for one group; merged across segments and processes by addition (the
    fleet index rebuilds them from its decision rows, ``report_from_sums``)."""

    decisions: int = 0
    sealed: int = 0
    summarized: int = 0
    et_sum: float = 0.0
    et_sq: float = 0.0
    etp_sum: float = 0.0
    etp_sq: float = 0.0
    full: int = 0
    factors: int = 0
    factors_traceable: int = 0
    no_factors: int = 0
    dr_ok: int = 0
    integrity_ok: int = 0
    tcs_sum: float = 0.0
    tcs_sq: float = 0.0
    window_ns: int = 0
    gap_ns: int = 0
    gaps: int = 0
    missing_cycles: int = 0
    dropped: int = 0
    anomalies: int = 0
    restarts: int = 0
    unknown: int = 0
    """Decisions whose ET is unknown (evidence in a recording not read): left out of the
    ET, ET_partial, fully traceable and TCS sums, counted here instead."""

    def merge(self, other: GroupSums) -> None:
        for name in self.__slots__:
            setattr(self, name, getattr(self, name) + getattr(other, name))


class SealOutcome(NamedTuple):
    """What the seal check and the gap rule said about one decision, and what it added to
    its group's TC sums (a fleet index stores these so it can sum them again)."""

    problems: list[str]
    """Why integrity fails ([] when it holds), ``integrity_problems``."""
    sealed: bool
    continuity: float
    window_ns: int
    """Time this decision adds to its robot's TC window (0 unsealed or a clock anomaly)."""
    gap: Gap | None
    """The gap its seal closes, if any."""
    dropped: int
    clock_anomaly: bool


@dataclass(frozen=True, slots=True)
class ScoredDecision:
    """One decision as metrics scored it: the parsed layers and every per-decision figure.

    Handed to a ``DecisionSink`` (the fleet index) so nothing is scored a second way."""

    cycle: Cycle
    segment: Segment
    group: str
    action: object
    belief: object
    perception: object
    execution: object
    score: DecisionScore
    dr_problems: tuple[str, ...]
    seal: SealOutcome
    tcs: float | None
    """TCS(d); None when its ET is unknown (``score.known`` is False)."""


DecisionSink = Callable[[ScoredDecision], None]


@dataclass(slots=True)
class CheckTally:
    """The failed checks of one rule on one robot so far: how many, the first and the last
    (time and cycle) in the order they were read."""

    failed: int
    first_t_ns: int
    first_cycle: int
    last_t_ns: int
    last_cycle: int

    def merge(self, later: CheckTally) -> None:
        """Add ``later``'s failures, read after these (the next segment in plan order)."""
        self.failed += later.failed
        self.last_t_ns, self.last_cycle = later.last_t_ns, later.last_cycle


@dataclass(slots=True)
class ScanResult:
    """What scanning one or more segments produced; merged in segment order."""

    groups: dict[str, GroupSums] = field(default_factory=dict)
    failures: list[DecisionFailure] = field(default_factory=list)
    failures_total: int = 0
    gaps: list[Gap] = field(default_factory=list)
    gaps_total: int = 0
    cycles: int = 0
    timing: list[tuple[float, int, CostHistogram | None]] = field(default_factory=list)
    """(mean ns, cycles, histogram if recorded) per segment with ``trace.timing``."""
    channels: dict[tuple[str, str], list[float]] = field(default_factory=dict)
    """(name, unit) -> [cycles, deviations logged, sum, max] of the execution channels."""
    external: dict[str, int] = field(default_factory=dict)
    checks: dict[tuple[str, str], CheckTally] = field(default_factory=dict)
    """(robot, rule) -> the failed execution checks of that rule, in chain order."""
    unread: dict[str, str] = field(default_factory=dict)
    """Recording name -> why it could not be read (refs into it unresolved), first seen."""

    def merge(self, other: ScanResult, limit: int) -> None:
        for name, why in other.unread.items():
            self.unread.setdefault(name, why)
        for state, count in other.external.items():
            self.external[state] = self.external.get(state, 0) + count
        for name, acc in other.groups.items():
            mine = self.groups.get(name)
            if mine is None:
                self.groups[name] = acc
            else:
                mine.merge(acc)
        self.failures.extend(other.failures[: max(0, limit - len(self.failures))])
        self.failures_total += other.failures_total
        self.gaps.extend(other.gaps[: max(0, limit - len(self.gaps))])
        self.gaps_total += other.gaps_total
        self.cycles += other.cycles
        self.timing.extend(other.timing)
        for key, (n, logged, total, top) in other.channels.items():
            sums = self.channels.setdefault(key, [0, 0, 0.0, -math.inf])
            sums[0] += n
            sums[1] += logged
            sums[2] += total
            sums[3] = max(sums[3], top)
        for key, tally in other.checks.items():
            earlier = self.checks.get(key)
            if earlier is None:
                self.checks[key] = tally
            else:
                earlier.merge(tally)


HAS_CHANNELS = b'"channels":[{'
"""Execution records with channels contain this (compact JSON, PROFILE §6); the others,
every profile 1.0 record among them, are not parsed again for it."""


def add_channels(into: dict[tuple[str, str], list[float]], execution: object) -> None:
    """Add an execution record's actuator channels to ``into`` (see ``ScanResult.channels``)."""
    channels = execution.get("channels") if isinstance(execution, dict) else None
    for channel in channels if isinstance(channels, list) else ():
        if not isinstance(channel, dict):
            continue
        name, unit = channel.get("name"), channel.get("unit")
        if not isinstance(name, str) or not isinstance(unit, str):
            continue
        sums = into.setdefault((name, unit), [0, 0, 0.0, -math.inf])
        sums[0] += 1
        deviation = channel.get("deviation")
        if isinstance(deviation, int | float) and math.isfinite(deviation):
            sums[1] += 1
            sums[2] += deviation
            sums[3] = max(sums[3], deviation)


MAY_FAIL_A_CHECK = b"false"
"""Every execution record with a failed check contains this: JSON has no other spelling of
``false`` (a literal cannot be escaped). Records without it (nearly all) are not parsed for
their checks."""


def failed_check_rules(execution: object) -> list[str]:
    """The rules of an execution record's checks that failed (``passed`` is false), in order."""
    checks = execution.get("checks") if isinstance(execution, dict) else None
    if not isinstance(checks, list):
        return []
    return [
        str(check.get("rule"))
        for check in checks
        if type(check) is dict and check.get("passed") is False
    ]


def add_failed_checks(
    into: dict[tuple[str, str], CheckTally], execution: object, robot: str, cycle: Cycle
) -> None:
    """Count an execution record's failed checks into ``into`` (see ``ScanResult.checks``)."""
    for rule in failed_check_rules(execution):
        tally = into.get((robot, rule))
        if tally is None:
            into[robot, rule] = CheckTally(1, cycle.t_ns, cycle.cycle, cycle.t_ns, cycle.cycle)
        else:
            tally.failed += 1
            tally.last_t_ns, tally.last_cycle = cycle.t_ns, cycle.cycle
