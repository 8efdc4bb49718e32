"""What checking rules over a log answers: typed results, one per rule and robot.

Times are ``*_ns`` in the log's clock; ``start``/``end`` beside them are the same times as a
command line takes them back (``LogClock.arg``: exact seconds, ISO on a wall clock).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

from trace_audit.jsonout import OMIT_EMPTY
from trace_audit.log_time import SECONDS_CLOCK, LogClock
from trace_runtime.gaps import Gap

__all__ = [
    "CheckResult",
    "GroupRule",
    "GroupRules",
    "Outcome",
    "RobotRules",
    "RuleResult",
    "SeenOutside",
    "Undecided",
    "UndecidedReason",
    "Violation",
]


class Outcome(StrEnum):
    """A rule's verdict over one robot's log in the window."""

    SATISFIED = "satisfied"
    """Every cycle that could be judged satisfies it, and the only cycles that could not
    are those whose horizon reaches past the log's first or last cycle."""
    VIOLATED = "violated"
    """At least one decidable cycle violates it (robustness < 0)."""
    NOT_DECIDABLE = "not_decidable"
    """No violation, but a gap, or a cycle that does not log a signal the rule reads, hides
    part of the window (or no cycle at all could be judged)."""


class UndecidedReason(StrEnum):
    GAP = "gap"
    """Cycles are missing (the one gap rule, ``trace_runtime.gaps``)."""
    MISSING_SIGNAL = "missing_signal"
    """A cycle does not log a signal the rule reads."""
    LOG_START = "log_start"
    LOG_END = "log_end"


@dataclass(frozen=True, slots=True)
class Violation:
    """Consecutive cycles where the rule's robustness is negative."""

    robot: str
    start_ns: int
    end_ns: int
    start: str
    end: str
    first_cycle: int
    last_cycle: int
    cycles: int
    robustness: float
    """The lowest robustness over these cycles (rtamt's)."""
    command: str | None
    """The decision in force at the first cycle."""
    explain: str
    """The command that explains that decision."""


@dataclass(frozen=True, slots=True)
class Undecided:
    """A stretch the rule cannot be judged on, and why: a gap (with it), a cycle without a
    signal the rule reads, or a horizon reaching past the log's start or end."""

    reason: UndecidedReason
    detail: str
    start_ns: int
    end_ns: int
    start: str
    end: str
    first_cycle: int
    last_cycle: int
    logged_cycles: int
    """Logged cycles in the stretch (not judged); a gap's own cycles are not logged."""
    gap: Gap | None = field(default=None, metadata={OMIT_EMPTY: True})


@dataclass(frozen=True, slots=True)
class RuleResult:
    """One rule over one robot's log in the window."""

    rule: str
    stl: str
    outcome: Outcome
    robustness: float | None
    """rtamt's robustness of the rule over the decidable cycles (the lowest of its body's);
    None when no cycle could be judged. An infinite value (a class never perceived) is
    ``null`` in JSON."""
    decidable_cycles: int
    violations: tuple[Violation, ...]
    undecided: tuple[Undecided, ...]
    unseen: tuple[str, ...] = field(default=(), metadata={OMIT_EMPTY: True})
    """Signals the rule reads that the robot's rows never show: a class never perceived
    (``nearest.*`` +inf throughout), a command never in force, a flag never raised, a
    channel, check or factor never logged. Often a typo; the outcome does not change."""
    seen_outside: tuple[SeenOutside, ...] = field(default=(), metadata={OMIT_EMPTY: True})
    """Of ``unseen``, with a window (``--from``/``--to``): those the log shows outside it,
    and where. The others the whole log never shows."""


@dataclass(frozen=True, slots=True)
class SeenOutside:
    """A signal a window never shows, where the rest of the robot's log shows it."""

    signal: str
    first_ns: int
    last_ns: int
    first_cycle: int
    last_cycle: int


@dataclass(frozen=True, slots=True)
class Skipped:
    """A robot a check did not judge, and why (the window misses its log, its clock)."""

    robot: str
    reason: str


@dataclass(frozen=True, slots=True)
class RobotRules:
    """Every rule over one robot's log."""

    robot: str
    period_ns: int
    """The sampling period of the discrete-time semantics (the log's cycle period)."""
    cycles: int
    """Logged cycles in the window."""
    rules: tuple[RuleResult, ...]
    clock: LogClock = SECONDS_CLOCK

    @property
    def violated(self) -> bool:
        return any(r.outcome is Outcome.VIOLATED for r in self.rules)


@dataclass(frozen=True, slots=True)
class GroupRule:
    """One rule over one group of a robot's cycles (``check --index --by robot,day``)."""

    rule: str
    outcome: Outcome
    robustness: float | None
    """The lowest robustness over the group's decidable cycles (None: none)."""
    decidable_cycles: int
    violations: int
    undecided: int

    @classmethod
    def of(cls, r: RuleResult) -> GroupRule:
        return cls(
            r.rule, r.outcome, r.robustness, r.decidable_cycles, len(r.violations), len(r.undecided)
        )


@dataclass(frozen=True, slots=True)
class GroupRules:
    """Every rule over one robot's cycles of one day (on a sim or monotonic clock, one run):
    the table a safety case quotes."""

    robot: str
    day: str
    cycles: int
    rules: tuple[GroupRule, ...]


@dataclass(frozen=True, slots=True)
class CheckResult:
    """Every rule of a rules file over each selected robot of a log (or of a fleet index)."""

    path: str
    rules_file: str
    robots: tuple[RobotRules, ...]
    groups: tuple[GroupRules, ...] = field(default=(), metadata={OMIT_EMPTY: True})
    """Per robot and day, with ``--by robot,day`` (``check --index``); empty otherwise."""
    skipped: tuple[Skipped, ...] = field(default=(), metadata={OMIT_EMPTY: True})
    """Robots of the log the window left nothing of, each with the reason."""

    @property
    def violated(self) -> bool:
        """Whether a rule is violated on any robot (the command's exit 1)."""
        return any(r.violated for r in self.robots)
