"""What ``trace-audit metrics`` reports: the per-group tables, failures, thresholds, costs.

Plain frozen dataclasses (``trace_audit.jsonout`` renders them); ``report`` fills them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from trace_audit.jsonout import OMIT_EMPTY
from trace_audit.log_time import LogClock
from trace_runtime.gaps import Gap

__all__ = [
    "AcrossGroups",
    "ChannelDeviation",
    "DecisionFailure",
    "FailedChecks",
    "GroupMetrics",
    "LoggingCost",
    "MetricsReport",
    "RuleFailures",
    "Stat",
    "ThresholdCheck",
]


@dataclass(frozen=True, slots=True)
class Stat:
    """A mean and its population std (ddof = 0), with what the std is taken across; both
    None when no value is known (``n`` = 0: no decision, or every one unknown)."""

    mean: float | None
    std: float | None
    n: int
    across: str


@dataclass(frozen=True, slots=True)
class GroupMetrics:
    """The metrics of one group of decisions (or of all of them), with the counts behind them."""

    name: str
    decisions: int
    sealed: int
    unsealed: int
    summarized: int
    """Decisions read from warm-tier summaries (sensor readings not kept, by design)."""
    et: Stat
    fully_traceable: int
    fully_traceable_share: Stat
    et_partial: Stat
    factors: int
    factors_traceable: int
    no_factors: int
    """Decisions whose action is missing or names no factors (ET(d) = 0 by definition)."""
    dr: float | None
    reconstructable: int
    not_reconstructable: int
    tc: float | None
    window_s: float
    gap_s: float
    gaps: int
    missing_cycles: int
    """Cycles the gaps would have held at the nominal period (sum of round(gap / period))."""
    declared_dropped: int
    """Sum of the seals' ``dropped`` counts: cycles the logger says it could not write."""
    clock_anomalies: int
    """Sealed cycles whose time is not after the previous sealed cycle's within a run of
    the robot's clock (no interval)."""
    integrity_ok: int
    integrity_failed: int
    tcs: Stat
    unknown: int = 0
    """Decisions whose ET, ET_partial and TCS are unknown: evidence they cite is in an
    external recording that could not be read (``MetricsReport.unread_recordings`` says
    why). ET, fully traceable, ET_partial and TCS are over the other decisions."""
    clock_restarts: int | None = field(default=None, metadata={OMIT_EMPTY: True})
    """Segments whose first sealed time is before the previous segment's last: the clock
    restarted (``trace_runtime.clock``; PROFILE section 4 allows it). The run starts a new
    window, as a log's first cycle does. None when there is none."""


@dataclass(frozen=True, slots=True)
class AcrossGroups:
    """Mean and population std of each group's value, taken across the groups."""

    by: str
    groups: int
    et: Stat
    fully_traceable_share: Stat
    et_partial: Stat
    tc: Stat | None
    dr: Stat | None


@dataclass(frozen=True, slots=True)
class DecisionFailure:
    """A decision that is not fully traceable, not reconstructable, or fails integrity."""

    cycle: int
    t_ns: int
    segment: str
    group: str
    et: float | None
    et_partial: float | None
    """None when unknown: evidence the decision cites is in a recording not read."""
    problems: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class ThresholdCheck:
    metric: str
    threshold: float
    value: float | None
    passed: bool


@dataclass(frozen=True, slots=True)
class ChannelDeviation:
    """Execution deviation of one actuator channel (profile 1.1) over the scored decisions,
    in the channel's own unit; ``cycles`` counts records naming the channel, ``logged``
    those that give its deviation (the mean and max are over those)."""

    name: str
    unit: str
    cycles: int
    logged: int
    mean: float | None
    max: float | None


@dataclass(frozen=True, slots=True)
class RuleFailures:
    """The failed checks of one rule in one robot's execution records: how many, and the
    first and the last to fail in the robot's chain order (its time and cycle)."""

    robot: str
    rule: str
    failed: int
    first_t_ns: int
    first_cycle: int
    last_t_ns: int
    last_cycle: int


@dataclass(frozen=True, slots=True)
class FailedChecks:
    """The execution checks (``/trace/execution`` ``checks``) that failed, per robot and
    rule (robots, then rules, in order of name), and the clock their times are in."""

    clock: LogClock
    rules: tuple[RuleFailures, ...]

    @property
    def total(self) -> int:
        return sum(r.failed for r in self.rules)


@dataclass(frozen=True, slots=True)
class LoggingCost:
    """The logger's control-thread cost per cycle as the log's writers measured it
    (``trace.timing`` metadata). Percentiles are None unless every timed segment carries a
    histogram (a writer may record only the mean); they are within 6.25 % (bucket width)."""

    cycles: int
    segments: int
    mean_ns: float
    p50_ns: int | None
    p99_ns: int | None
    max_ns: int | None


@dataclass(frozen=True, slots=True)
class MetricsReport:
    """Everything ``trace-audit metrics`` shows: definitions, tables, failures, thresholds."""

    logs: tuple[str, ...]
    segments: tuple[str, ...]
    skipped_segments: tuple[str, ...]
    """Copies of a segment not read because another tier's copy is (``preferred_copies``)."""
    unreadable: tuple[str, ...]
    """Files of the log that could not be read, each ``path: reason``; the rest is scored."""
    by: str | None
    definitions: dict[str, str]
    overall: GroupMetrics
    groups: tuple[GroupMetrics, ...]
    across_groups: AcrossGroups | None
    logging_time: str
    failures: tuple[DecisionFailure, ...]
    failures_total: int
    gaps: tuple[Gap, ...]
    gaps_total: int
    thresholds: tuple[ThresholdCheck, ...]
    elapsed_s: float
    cycles_per_s: float
    logging_cost: LoggingCost | None = field(default=None, metadata={OMIT_EMPTY: True})
    """The logger's own control-thread cost per cycle, from the segments' ``trace.timing``."""
    channel_deviation: tuple[ChannelDeviation, ...] = field(default=(), metadata={OMIT_EMPTY: True})
    """Per actuator channel of the execution records (profile 1.1), by name and unit."""
    failed_checks: FailedChecks | None = field(default=None, metadata={OMIT_EMPTY: True})
    """The execution checks that failed, per robot and rule; None when none did (or the
    report comes from the fleet index)."""
    robots: tuple[str, ...] = field(default=(), metadata={OMIT_EMPTY: True})
    """The robots the report was asked for (``robots``, ``--robot``); empty: every robot of
    the logs."""
    external_refs: dict[str, int] = field(default_factory=dict)
    """Evidence refs into external recordings, by what became of them: ``resolved``,
    ``broken`` (recording given, message missing or changed) and ``unresolved`` (recording
    not given: not checked). Counted per citation in the perception records."""
    unread_recordings: tuple[str, ...] = field(default=(), metadata={OMIT_EMPTY: True})
    """Why each recording the decisions cite could not be read ("recording X not found at
    P", "... not given"): what makes decisions unknown."""
    clock: LogClock | None = field(default=None, metadata={OMIT_EMPTY: True})
    """The clock of the listed failures' and gaps' times, for showing them (None: the sums
    came from elsewhere); --json keeps them as ``t_ns``."""
    not_in_index: tuple[str, ...] = field(default=(), metadata={OMIT_EMPTY: True})
    """Fields a report from the fleet index cannot fill (the index holds no logger timing,
    execution channels or external refs): read them from the logs, not as zero."""

    @property
    def passed(self) -> bool:
        return all(check.passed for check in self.thresholds)
