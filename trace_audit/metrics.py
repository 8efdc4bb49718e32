"""Auditability metrics from logged artifacts only: ET, ET_partial, TC, DR and TCS.

Definitions (docs/metrics.md is the long form; every number here comes from the log):

- A *decision* is a cycle the reader yields: sealed, or an unsealed tail of a crashed writer.
  Its factors F_d are ``rationale.factors`` of its ``/trace/action`` record.
- **ET(d)**: share of F_d whose chain (``trace_audit.chains``) is documented down to a
  sensor reading its evidence ref resolves to. No action or no factors: ET(d) = 0.
- **ET_partial(d)**: mean over F_d of documented depth / expected depth (5 for a factor on a
  derived-state node, 4 for one on an entity node).
- **TC** = 1 - sum(gaps) / window over the sealed cycles of each robot, in time order. The
  interval between two consecutive sealed cycles is a gap when it exceeds the nominal period
  (``trace.session`` ``period_ns``) by more than ``gap_tolerance`` periods; the gap is the
  time beyond one period (the rule is ``trace_runtime.gaps``). The window is last - first
  sealed time + one period. A gap is counted in the group of the sealed cycle that ends it.
  Seals' ``dropped`` counts are summed separately as declared drops.
- **DR(d)** = 1 when the action is logged (a command), its alternatives are logged (at
  least one), and its rationale is complete: not truncated, factors present, and
  counterfactuals present or ``counterfactuals_none_applicable``. A sealed cycle without an
  action is not reconstructable.
- **Integrity(d)** = 1 when the one seal check (``trace_runtime.integrity.verify_cycle``)
  passes: sealed, every layer payload it holds has the digest its seal names, every layer
  the seal names is present, evidenced readings match their refs, and the seal's ``prev``
  is the digest of the robot's previous seal (the segment's ``prev_seal`` for the first).
- **TCS(d)** = weighted mean of ET, ET_partial, DR, continuity and integrity (``TCSWeights``),
  forced to 0 when integrity fails and ``integrity_gate`` is on. Continuity(d) is 1, or
  period / interval when the interval that ends at d holds a gap.

Stds are population stds (ddof = 0); each ``Stat`` says what it is taken across.
Nothing here reads an injected-fault flag or a simulator's ground truth.
"""

from __future__ import annotations

import contextlib
import math
import os
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, NamedTuple, get_args

from trace_audit.chains import (
    DEFAULT_SENSOR_WINDOW,
    EXPECTED_DEPTH_ENTITY,
    EXPECTED_DEPTH_STATE,
    DecisionChains,
    DecisionScore,
    SensorWindow,
    score_layers,
    trace_layers,
)
from trace_audit.evidence import open_recordings
from trace_audit.jsonout import OMIT_EMPTY
from trace_runtime.chain import digest
from trace_runtime.costs import TIMING_METADATA, CostHistogram
from trace_runtime.cycles import Cycle
from trace_runtime.errors import LogReadError, UsageError
from trace_runtime.gaps import DEFAULT_GAP_TOLERANCE, Gap, continuity, find_gap
from trace_runtime.logset import Log, open_logs
from trace_runtime.reader import Segment, open_segment
from trace_runtime.records import (
    TOPIC_ACTION,
    TOPIC_BELIEF,
    TOPIC_EXECUTION,
    TOPIC_PERCEPTION,
    TOPIC_SEAL,
)
from trace_runtime.seal_check import SealStatus, verify_cycle

__all__ = [
    "GROUP_BYS",
    "METRIC_NAMES",
    "AcrossGroups",
    "ChannelDeviation",
    "DecisionFailure",
    "Gap",
    "GroupBy",
    "GroupMetrics",
    "GroupSums",
    "LoggingCost",
    "MetricsConfig",
    "MetricsReport",
    "ScoredDecision",
    "SealOutcome",
    "Stat",
    "TCSWeights",
    "ThresholdCheck",
    "compute_metrics",
    "parse_thresholds",
    "report_from_sums",
    "scenario_of",
    "score_segment",
]

GroupBy = Literal["scenario", "segment", "robot", "hour"]
GROUP_BYS: tuple[str, ...] = get_args(GroupBy)
NO_SCENARIO = "(none)"
SCENARIO_FLAG = "scenario:"

ProgressCallback = Callable[[int, int | None], None]
"""Called with (cycles done, cycles expected or None) as the scan advances."""

_PROGRESS_EVERY = 2048


# --- configuration ---------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class TCSWeights:
    """Weights of the per-decision trust score TCS(d); they need not sum to 1."""

    et: float = 0.3
    et_partial: float = 0.1
    dr: float = 0.3
    continuity: float = 0.1
    integrity: float = 0.2
    integrity_gate: bool = True
    """TCS(d) = 0 when integrity fails: a record that may be altered earns no trust."""

    def __post_init__(self) -> None:
        values = (self.et, self.et_partial, self.dr, self.continuity, self.integrity)
        if any(v < 0 or not math.isfinite(v) for v in values) or sum(values) <= 0:
            raise UsageError("TCS weights must be finite, >= 0, and not all 0")

    @classmethod
    def parse(cls, text: str) -> TCSWeights:
        """Parse ``et=0.3,et_partial=0.1,dr=0.3,continuity=0.1,integrity=0.2,gate=1``."""
        values: dict[str, Any] = {}
        for item in _items(text):
            key, value = _split_pair(item, "TCS weight")
            key = key.lower()
            if key in ("gate", "integrity_gate"):
                if value.lower() not in ("0", "1", "true", "false", "on", "off"):
                    raise UsageError(f"TCS gate must be on or off, got {value!r}")
                values["integrity_gate"] = value.lower() in ("1", "true", "on")
            elif key in ("et", "et_partial", "dr", "continuity", "integrity"):
                values[key] = _number(value, f"TCS weight {key}")
            else:
                raise UsageError(
                    f"unknown TCS weight {key!r} "
                    "(use et, et_partial, dr, continuity, integrity, gate)"
                )
        return cls(**values)


METRIC_NAMES = ("ET", "ET_full", "ET_partial", "TC", "DR", "TCS")
"""Names ``--fail-under`` accepts: ET mean, share fully traceable, ET_partial, TC, DR, TCS."""


def parse_thresholds(text: str) -> dict[str, float]:
    """Parse ``ET=0.95,DR=95%`` into fractions; raise ``UsageError`` on anything else."""
    lookup = {name.lower(): name for name in METRIC_NAMES}
    out: dict[str, float] = {}
    for item in _items(text):
        key, value = _split_pair(item, "threshold")
        name = lookup.get(key.lower())
        if name is None:
            raise UsageError(
                f"unknown metric {key!r} in thresholds (use {', '.join(METRIC_NAMES)})"
            )
        if value.endswith("%"):
            number = _number(value[:-1], f"threshold {name}") / 100.0
        else:
            number = _number(value, f"threshold {name}")
            if number > 1.0:
                raise UsageError(f"threshold {name}={value} is above 1; write {value}% for percent")
        if not 0.0 <= number <= 1.0:
            raise UsageError(f"threshold {name}={value} is outside [0, 1]")
        out[name] = number
    return out


@dataclass(frozen=True, slots=True)
class MetricsConfig:
    """How ``compute_metrics`` reads and scores a log."""

    by: GroupBy | None = None
    gap_tolerance: float = DEFAULT_GAP_TOLERANCE
    """An interval between sealed cycles is a gap when > (1 + tolerance) x nominal period
    (the rule is ``trace_runtime.gaps``; this only overrides its tolerance)."""
    sensor_window: int = DEFAULT_SENSOR_WINDOW
    """Evidence refs resolve against this many cycles before the decision (and its own)."""
    weights: TCSWeights = field(default_factory=TCSWeights)
    thresholds: Mapping[str, float] = field(default_factory=dict)
    max_listed: int = 10_000
    """At most this many failing decisions and gaps are kept for listing (all are counted)."""
    workers: int = 1
    """Processes to spread segments over (1: in this process)."""
    start_ns: int | None = None
    end_ns: int | None = None
    evidence: tuple[str, ...] = ()
    """External recordings (MCAP files, rosbag2 directories) that evidence refs may name; a
    ref into one resolves there (digest checked), a ref into one not given does not."""

    def __post_init__(self) -> None:
        if self.by is not None and self.by not in GROUP_BYS:
            raise UsageError(f"cannot group by {self.by!r} (use {', '.join(GROUP_BYS)})")
        if not (self.gap_tolerance >= 0 and math.isfinite(self.gap_tolerance)):
            raise UsageError(f"gap tolerance must be >= 0, got {self.gap_tolerance}")
        if self.sensor_window < 0:
            raise UsageError(f"sensor window must be >= 0 cycles, got {self.sensor_window}")
        if self.workers < 1:
            raise UsageError(f"workers must be >= 1, got {self.workers}")
        if self.max_listed < 0:
            raise UsageError(f"max_listed must be >= 0, got {self.max_listed}")
        if self.start_ns is not None and self.end_ns is not None and self.end_ns < self.start_ns:
            raise UsageError("the analysis window ends before it starts")
        unknown = set(self.thresholds) - set(METRIC_NAMES)
        if unknown:
            raise UsageError(f"unknown metric(s) in thresholds: {', '.join(sorted(unknown))}")


# --- results ---------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Stat:
    """A mean and its population std (ddof = 0), with what the std is taken across."""

    mean: float
    std: float
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
    """Sealed cycles whose time is not after the previous sealed cycle's within a segment
    (no interval)."""
    integrity_ok: int
    integrity_failed: int
    tcs: Stat
    clock_restarts: int | None = field(default=None, metadata={OMIT_EMPTY: True})
    """Segments whose first sealed time is not after the previous segment's last: a restart
    with a monotonic clock (PROFILE section 4 allows it). The run starts a new window, as a
    log's first cycle does. None when there is none."""


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
    et: float
    et_partial: float
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
    external_refs: dict[str, int] = field(default_factory=dict)
    """Evidence refs into external recordings, by what became of them: ``resolved``,
    ``broken`` (recording given, message missing or changed) and ``unresolved`` (recording
    not given: not checked). Counted per citation in the perception records."""
    not_in_index: tuple[str, ...] = field(default=(), metadata={OMIT_EMPTY: True})
    """Fields a report from the fleet index cannot fill (the index holds no logger timing,
    execution channels or external refs): read them from the logs, not as zero."""

    @property
    def passed(self) -> bool:
        return all(check.passed for check in self.thresholds)


# --- accumulation ------------------------------------------------------------------------------


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

    def merge(self, other: GroupSums) -> None:
        for name in self.__slots__:
            setattr(self, name, getattr(self, name) + getattr(other, name))


@dataclass(slots=True)
class _Stream:
    """Where one robot's sealed sequence stands: the last sealed time and seal digest."""

    prev_t_ns: int | None = None
    prev_cycle: int = -1
    prev_seal: str | None = None
    prev_segment: str = ""
    """The file the last sealed cycle came from."""


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
    action: Any
    belief: Any
    perception: Any
    execution: Any
    score: DecisionScore
    dr_problems: tuple[str, ...]
    seal: SealOutcome
    tcs: float


DecisionSink = Callable[[ScoredDecision], None]


@dataclass(slots=True)
class _Partial:
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

    def merge(self, other: _Partial, limit: int) -> None:
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


class _Scanner:
    """Scores the cycles of one robot's segments in order, carrying chain and window state."""

    def __init__(
        self, config: MetricsConfig, partial: _Partial, sink: DecisionSink | None = None
    ) -> None:
        self.config = config
        self.partial = partial
        self.sink = sink
        self.window = SensorWindow(config.sensor_window, open_recordings(config.evidence))
        self.stream = _Stream()
        self.session_prev: str | None = None

    def scan(self, segment: Segment, progress: Callable[[int], None] | None = None) -> None:
        cfg = self.config
        session = segment.session
        # The first seal read links to the session's prev_seal, unless a start time cut the
        # segment: then the seal before it was not read and the link cannot be checked here.
        cut = cfg.start_ns is not None and segment.info.start_ns < cfg.start_ns
        self.session_prev = None if cut else session.prev_seal
        group_of = self._grouper(segment)
        done = 0
        for cycle in segment.iter_cycles(cfg.start_ns, cfg.end_ns):
            done += 1
            if progress is not None and done % _PROGRESS_EVERY == 0:
                progress(_PROGRESS_EVERY)
            self._score(cycle, segment, group_of)
        self.partial.cycles += done
        if progress is not None:
            progress(done % _PROGRESS_EVERY)
        timing = segment.metadata.get(TIMING_METADATA)
        if timing:
            with contextlib.suppress(KeyError, ValueError):  # a malformed record: not timed
                self.partial.timing.append(
                    (
                        float(timing["commit_mean_ns"]),
                        int(timing.get("cycles", done)),
                        CostHistogram.from_metadata(timing),
                    )
                )

    def _grouper(self, segment: Segment) -> Callable[[Cycle], str]:
        """How this segment's cycles are grouped (``--by``)."""
        by = self.config.by
        if by is None:
            return lambda _cycle: "all"
        if by == "segment":
            name = segment.path.name
            return lambda _cycle: name
        if by == "robot":
            robot = segment.session.robot_id
            return lambda _cycle: robot
        if by == "scenario":
            return lambda cycle: scenario_of(cycle.layer(TOPIC_EXECUTION))
        return lambda cycle: time.strftime(
            "%Y-%m-%d %H:00", time.gmtime(cycle.t_ns // 1_000_000_000)
        )

    def _count_external(self, perception: Any) -> None:
        """Tally the perception's refs into external recordings by resolved / broken /
        unresolved (a ref's check is remembered by the window, so a reading cited cycle
        after cycle is read once)."""
        if not isinstance(perception, dict):
            return
        tally = self.partial.external
        for entity in perception.get("entities") or ():
            for evidence in (entity.get("evidence") or ()) if isinstance(entity, dict) else ():
                ref = evidence.get("ref") if isinstance(evidence, dict) else None
                if isinstance(ref, dict) and type(ref.get("recording")) is str:
                    state = self.window.external_state(ref)
                    tally[state] = tally.get(state, 0) + 1

    def _score(self, cycle: Cycle, segment: Segment, group_of: Callable[[Cycle], str]) -> None:
        """Score one decision into its group's sums; list it when it fails."""
        window = self.window
        window.push(cycle.sensors)
        # Each layer is parsed once: ET, DR and the seal check's evidence step share it.
        action = cycle.layer(TOPIC_ACTION)
        belief = cycle.layer(TOPIC_BELIEF)
        perception = cycle.layer(TOPIC_PERCEPTION)
        score = score_layers(action, belief, perception, window=window)
        if perception is not None and _may_cite_recording(cycle.payloads.get(TOPIC_PERCEPTION)):
            self._count_external(perception)
        missing_dr = dr_problems(action)
        execution = cycle.payloads.get(TOPIC_EXECUTION)
        if execution is not None and _HAS_CHANNELS in execution:  # parsed only when it has
            _add_channels(self.partial.channels, cycle.layer(TOPIC_EXECUTION))
        group = group_of(cycle)
        partial = self.partial
        acc = partial.groups.get(group)
        if acc is None:
            acc = partial.groups[group] = GroupSums()
        seal = self._seal_and_gap(cycle, segment, acc, perception)
        integrity, continuity_d = seal.problems, seal.continuity
        et, etp = score.et, score.et_partial
        factors, traceable = score.factors, score.traceable
        full = factors > 0 and traceable == factors
        dr_ok, intact = not missing_dr, not integrity
        acc.decisions += 1
        if cycle.summary is not None:
            acc.summarized += 1
        acc.et_sum += et
        acc.et_sq += et * et
        acc.etp_sum += etp
        acc.etp_sq += etp * etp
        acc.full += full
        acc.factors += factors
        acc.factors_traceable += traceable
        acc.no_factors += factors == 0
        acc.dr_ok += dr_ok
        acc.integrity_ok += intact
        tcs = trust_score(
            self.config.weights,
            et=et,
            et_partial=etp,
            dr_ok=dr_ok,
            continuity=continuity_d,
            intact=intact,
        )
        acc.tcs_sum += tcs
        acc.tcs_sq += tcs * tcs
        if self.sink is not None:
            execution = cycle.layer(TOPIC_EXECUTION)
            self.sink(
                ScoredDecision(
                    cycle,
                    segment,
                    group,
                    action,
                    belief,
                    perception,
                    execution,
                    score,
                    tuple(missing_dr),
                    seal,
                    tcs,
                )
            )
        if full and dr_ok and intact:
            return
        partial.failures_total += 1
        if len(partial.failures) >= self.config.max_listed:
            return
        et_problems = (
            ()
            if full
            else _et_problems(
                trace_layers(cycle.cycle, cycle.t_ns, action, belief, perception, window=window)
            )
        )
        partial.failures.append(
            DecisionFailure(
                cycle.cycle,
                cycle.t_ns,
                segment.path.name,
                group,
                et,
                etp,
                (
                    *et_problems,
                    *(f"DR: {p}" for p in missing_dr),
                    *(f"integrity: {p}" for p in integrity),
                ),
            )
        )

    def _seal_and_gap(
        self, cycle: Cycle, segment: Segment, acc: GroupSums, perception: Any
    ) -> SealOutcome:
        """Integrity problems of the cycle (the one seal check, ``verify_cycle``) and its
        continuity; a sealed cycle closes an interval, which the one gap rule judges."""
        stream = self.stream
        expected = stream.prev_seal if stream.prev_seal is not None else self.session_prev
        parsed = perception if TOPIC_PERCEPTION in cycle.payloads else None
        status = verify_cycle(
            cycle, expected, perception_json=parsed, sensor_digest=self.window.digest_of
        )
        integrity = [] if status.ok else integrity_problems(status)
        if status.state == "unsealed":
            return SealOutcome(integrity, False, 0.0, 0, None, 0, False)
        acc.sealed += 1
        stream.prev_seal = status.seal_digest
        acc.dropped += status.dropped
        period = segment.session.period_ns
        prev_t = stream.prev_t_ns
        t_ns = cycle.t_ns
        continuity_d = 1.0
        window_ns = 0
        gap: Gap | None = None
        restart = (
            prev_t is not None
            and t_ns <= prev_t
            and stream.prev_segment not in ("", segment.path.name)
        )
        if prev_t is None or restart:
            window_ns = period
            acc.window_ns += period
            acc.restarts += restart
        elif t_ns <= prev_t:
            acc.anomalies += 1
        else:
            interval = window_ns = t_ns - prev_t
            acc.window_ns += interval
            gap = find_gap(
                stream.prev_cycle,
                prev_t,
                cycle.cycle,
                t_ns,
                period,
                tolerance=self.config.gap_tolerance,
                declared_dropped=status.dropped,
                robot=segment.session.robot_id,
            )
            if gap is not None:
                acc.gap_ns += gap.gap_ns
                acc.gaps += 1
                acc.missing_cycles += gap.missing_cycles
                continuity_d = continuity(interval, period, self.config.gap_tolerance)
                self.partial.gaps_total += 1
                if len(self.partial.gaps) < self.config.max_listed:
                    self.partial.gaps.append(gap)
        stream.prev_t_ns = t_ns
        stream.prev_cycle = cycle.cycle
        stream.prev_segment = segment.path.name
        anomaly = prev_t is not None and t_ns <= prev_t and not restart
        return SealOutcome(integrity, True, continuity_d, window_ns, gap, status.dropped, anomaly)

    def prefill(self, segment: Segment) -> None:
        """Load the chain and window state at the end of ``segment`` (the one before ours)."""
        cfg = self.config
        tail: list[Cycle] = []
        last_sealed: Cycle | None = None
        for cycle in segment.iter_cycles(cfg.start_ns, cfg.end_ns, reverse=True):
            if len(tail) <= cfg.sensor_window:
                tail.append(cycle)
            if last_sealed is None and TOPIC_SEAL in cycle.payloads:
                last_sealed = cycle
            if last_sealed is not None and len(tail) > cfg.sensor_window:
                break
        for cycle in reversed(tail):
            self.window.push(cycle.sensors)
        if last_sealed is not None:
            self.stream.prev_t_ns = last_sealed.t_ns
            self.stream.prev_cycle = last_sealed.cycle
            self.stream.prev_segment = segment.path.name
            self.stream.prev_seal = digest(last_sealed.payloads[TOPIC_SEAL])


def integrity_problems(status: SealStatus) -> list[str]:
    """Why a decision fails integrity, from the one seal check; [] when it holds."""
    if status.state == "unsealed":
        return ["not sealed"]
    problems = [f"{topic} does not match its seal digest" for topic in status.modified]
    problems += [f"{topic} is not named by the seal" for topic in status.extra]
    problems += [f"{topic} is named by the seal but missing" for topic in status.missing]
    problems += [
        f"sensor reading {reading} does not match the digest its evidence ref names"
        for reading in status.evidence_mismatch
    ]
    if status.state == "modified" and not problems:
        problems.append(status.detail)  # a malformed seal, or one naming another cycle
    if status.link == "broken":
        problems.append("hash chain broken: prev is not the previous seal's digest")
    return problems


def trust_score(
    weights: TCSWeights,
    *,
    et: float,
    et_partial: float,
    dr_ok: bool,
    continuity: float,
    intact: bool,
) -> float:
    """TCS(d): the weighted mean of ET, ET_partial, DR, continuity and integrity (docs/metrics.md);
    0 when integrity fails and the gate is on."""
    if not intact and weights.integrity_gate:
        return 0.0
    total = weights.et + weights.et_partial + weights.dr + weights.continuity + weights.integrity
    return (
        weights.et * et
        + weights.et_partial * et_partial
        + weights.dr * dr_ok
        + weights.continuity * continuity
        + weights.integrity * intact
    ) / total


def dr_problems(action: Any) -> list[str]:
    """Why a decision is not reconstructable (DR = 0); [] when DR = 1. ``action`` is JSON."""
    if not isinstance(action, dict) or not action.get("command"):
        return ["action not logged"]
    problems: list[str] = []
    if not action.get("alternatives"):
        problems.append("no alternatives logged")
    rationale = action.get("rationale")
    if not isinstance(rationale, dict):
        problems.append("no rationale logged")
        return problems
    if rationale.get("truncated"):
        problems.append("rationale truncated")
    factors = rationale.get("factors")
    if not factors or not isinstance(factors, list):
        problems.append("rationale names no factors")
    if not action.get("counterfactuals") and not action.get("counterfactuals_none_applicable"):
        problems.append("no counterfactuals and not declared none-applicable")
    return problems


def _et_problems(chains: DecisionChains) -> list[str]:
    if chains.reason:
        return [f"ET: {chains.reason}"]
    out: list[str] = []
    for factor in chains.factors:
        link = factor.missing
        if link is not None:
            label = f"{factor.node} ({factor.name})" if factor.name else factor.node
            out.append(
                f"ET: factor {label}: {link.level} missing ({link.detail}); "
                f"depth {factor.depth}/{factor.expected_depth}"
            )
    return out


def scenario_of(execution: Any) -> str:
    """The scenario an execution record's ``scenario:NAME`` flag names, or ``(none)``."""
    if isinstance(execution, dict):
        for flag in execution.get("flags") or ():
            if isinstance(flag, str) and flag.startswith(SCENARIO_FLAG):
                return flag[len(SCENARIO_FLAG) :] or NO_SCENARIO
    return NO_SCENARIO


# --- segments ----------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _Task:
    path: str
    previous: str | None
    config: MetricsConfig


def _plan(log: Log) -> list[tuple[str, list[Segment]]]:
    """Each robot's segments in chain order, robots in order of their first record."""
    plan = [(robot, log.segments_of(robot)) for robot in log.robots]
    plan.sort(key=lambda item: min(s.info.start_ns for s in item[1]))
    return plan


def _shadowed(log: Log) -> list[str]:
    out: list[str] = []
    for copy in log.shadowed:
        key = (copy.session.robot_id, copy.session.segment, copy.session.first_cycle)
        read = next(
            (
                s
                for s in log.segments
                if (s.session.robot_id, s.session.segment, s.session.first_cycle) == key
            ),
            None,
        )
        where = ", which is read" if read is None else f" {read.path}, which is read"
        out.append(f"{copy.path} (a copy of the same segment as{where})")
    return out


def score_segment(
    path: str | Path,
    previous: str | Path | None,
    config: MetricsConfig,
    sink: DecisionSink | None = None,
) -> _Partial:
    """Score one segment as a run over the whole log would: the tail of the robot's
    ``previous`` segment is read first, so chain links, gaps and refs across the boundary
    come out the same. Each decision is also handed to ``sink`` (the fleet index)."""
    partial = _Partial()
    scanner = _Scanner(config, partial, sink)
    if previous is not None:
        scanner.prefill(open_segment(previous))
    scanner.scan(open_segment(path))
    return partial


def _run_task(task: _Task) -> _Partial:
    return score_segment(task.path, task.previous, task.config)


def _usable_cpus() -> int:
    """CPUs this process may run on (its affinity mask, e.g. a container's share)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0)) or 1
    return os.cpu_count() or 1


def _expected_cycles(segment: Segment) -> int:
    return segment.info.channels.get(TOPIC_SEAL, 0)


# --- the entry point ---------------------------------------------------------------------------


def compute_metrics(
    paths: Sequence[str | Path],
    config: MetricsConfig | None = None,
    *,
    progress: ProgressCallback | None = None,
    executor: Executor | None = None,
) -> MetricsReport:
    """Score every decision in the given logs (files, directories or log roots) in one pass.

    Memory is bounded: cycles are streamed, sums accumulated, and at most
    ``config.max_listed`` failing decisions and gaps kept for listing. Given an
    ``executor`` (e.g. a Dask cluster's, ``trace_audit.fleet.cluster``), segments are
    scored there, one task each, instead of in local processes; the report is the same.
    """
    cfg = config or MetricsConfig()
    started = time.perf_counter()
    log = open_logs(paths)
    plan = _plan(log)
    expected = sum(_expected_cycles(s) for _, segs in plan for s in segs) or None
    total = _Partial()
    done = 0

    def advance(n: int) -> None:
        nonlocal done
        done += n
        if progress is not None:
            progress(done, expected)

    # A cluster's worker resolves a relative path in its own directory: name files by
    # absolute path there (the report still names them as given).
    def where(path: Path) -> str:
        return str(path.absolute()) if executor is not None else str(path)

    tasks = [
        _Task(where(seg.path), where(segs[i - 1].path) if i else None, cfg)
        for _robot, segs in plan
        for i, seg in enumerate(segs)
    ]
    workers = min(cfg.workers, len(tasks), _usable_cpus())
    if executor is not None:
        _fan_out(executor, tasks, plan=plan, total=total, advance=advance, limit=cfg.max_listed)
    elif workers <= 1:
        for _robot, segments in plan:
            partial = _Partial()
            scanner = _Scanner(cfg, partial)
            for segment in segments:
                scanner.scan(segment, advance)
            total.merge(partial, cfg.max_listed)
    else:
        # Each task scores one segment; it first reads the tail of the robot's previous
        # segment, so chain links, gaps and refs across the boundary come out as in one pass.
        # The longest segments start first (a short one left for last keeps both workers
        # busy to the end); the partials are merged in plan order whatever order they finish
        # in, so the sums and the listed failures are the same in every run.
        with ProcessPoolExecutor(max_workers=workers) as pool:
            _fan_out(pool, tasks, plan=plan, total=total, advance=advance, limit=cfg.max_listed)
    elapsed = time.perf_counter() - started
    segments_read = tuple(str(s.path) for _, segs in plan for s in segs)
    report = _report(
        paths, cfg, log=log, total=total, segments=segments_read, elapsed=elapsed, by=cfg.by
    )
    if report.overall.decisions == 0 and cfg.start_ns is None and cfg.end_ns is None:
        # As info, explain and verify say it: nothing to score is an empty log, not 0 %.
        raise LogReadError(str(paths[0]), "the log holds no decision cycles")
    return report


def _fan_out(
    executor: Executor,
    tasks: list[_Task],
    *,
    plan: list[tuple[str, list[Segment]]],
    total: _Partial,
    advance: Callable[[int], None],
    limit: int,
) -> None:
    """Score each task on ``executor``; merge the partials in plan order."""
    sizes = [s.info.bytes for _robot, segs in plan for s in segs]
    order = sorted(range(len(tasks)), key=lambda i: -sizes[i])
    futures = {i: executor.submit(_run_task, tasks[i]) for i in order}
    for future in as_completed(futures.values()):
        advance(future.result().cycles)
    for i in range(len(tasks)):
        total.merge(futures[i].result(), limit)


def report_from_sums(
    sources: Sequence[str],
    cfg: MetricsConfig,
    groups: Mapping[str, GroupSums],
    *,
    by: str | None,
    segments: tuple[str, ...],
    cycles: int,
    elapsed: float,
) -> MetricsReport:
    """A report from sums gathered elsewhere (the fleet index's decision rows): the same
    tables, stds and thresholds as a scan of the logs; nothing listed, timing not logged.
    ``by`` names the grouping of ``groups`` (any label: the index groups by more keys)."""
    total = _Partial(groups=dict(groups), cycles=cycles)
    report = _report(sources, cfg, log=None, total=total, segments=segments, elapsed=elapsed, by=by)
    if report.overall.decisions == 0:
        raise LogReadError(str(sources[0]) if sources else "index", "no decisions selected")
    return report


def _report(
    paths: Sequence[str | Path],
    cfg: MetricsConfig,
    *,
    log: Log | None,
    total: _Partial,
    segments: tuple[str, ...],
    elapsed: float,
    by: str | None,
) -> MetricsReport:
    overall_acc = GroupSums()
    for acc in total.groups.values():
        overall_acc.merge(acc)
    overall = _group("all", overall_acc)
    groups: tuple[GroupMetrics, ...] = ()
    across: AcrossGroups | None = None
    if by is not None:
        groups = tuple(_group(name, acc) for name, acc in total.groups.items())
        across = _across(by, groups)
    checks = tuple(_check(name, threshold, overall) for name, threshold in cfg.thresholds.items())
    failures = tuple(sorted(total.failures, key=lambda f: (f.t_ns, f.cycle)))
    gaps = tuple(sorted(total.gaps, key=lambda g: (g.after_t_ns, g.robot)))
    cost = _logging_cost(total.timing)
    return MetricsReport(
        logs=tuple(str(p) for p in paths),
        segments=segments,
        skipped_segments=tuple(_shadowed(log)) if log is not None else (),
        unreadable=tuple(f"{p.path}: {p.reason}" for p in log.problems) if log else (),
        by=by,
        definitions=_definitions(cfg),
        overall=overall,
        groups=groups,
        across_groups=across,
        logging_time=_timing(cost),
        failures=failures,
        failures_total=total.failures_total,
        gaps=gaps,
        gaps_total=total.gaps_total,
        thresholds=checks,
        elapsed_s=elapsed,
        logging_cost=cost,
        channel_deviation=_channel_deviation(total.channels),
        cycles_per_s=total.cycles / elapsed if elapsed > 0 else 0.0,
        external_refs=dict(sorted(total.external.items())),
    )


def _stat(total: float, squares: float, n: int, across: str) -> Stat:
    if n == 0:
        return Stat(0.0, 0.0, 0, across)
    mean = total / n
    return Stat(mean, math.sqrt(max(0.0, squares / n - mean * mean)), n, across)


def _group(name: str, acc: GroupSums) -> GroupMetrics:
    n = acc.decisions
    return GroupMetrics(
        name=name,
        decisions=n,
        sealed=acc.sealed,
        unsealed=n - acc.sealed,
        summarized=acc.summarized,
        et=_stat(acc.et_sum, acc.et_sq, n, "decisions"),
        fully_traceable=acc.full,
        fully_traceable_share=_stat(acc.full, acc.full, n, "decisions"),
        et_partial=_stat(acc.etp_sum, acc.etp_sq, n, "decisions"),
        factors=acc.factors,
        factors_traceable=acc.factors_traceable,
        no_factors=acc.no_factors,
        dr=acc.dr_ok / n if n else None,
        reconstructable=acc.dr_ok,
        not_reconstructable=n - acc.dr_ok,
        tc=1.0 - acc.gap_ns / acc.window_ns if acc.window_ns > 0 else None,
        window_s=acc.window_ns / 1e9,
        gap_s=acc.gap_ns / 1e9,
        gaps=acc.gaps,
        missing_cycles=acc.missing_cycles,
        declared_dropped=acc.dropped,
        clock_anomalies=acc.anomalies,
        integrity_ok=acc.integrity_ok,
        integrity_failed=n - acc.integrity_ok,
        tcs=_stat(acc.tcs_sum, acc.tcs_sq, n, "decisions"),
        clock_restarts=acc.restarts or None,
    )


def _spread(values: Iterable[float | None], across: str) -> Stat | None:
    present = [v for v in values if v is not None]
    if not present:
        return None
    mean = sum(present) / len(present)
    var = sum((v - mean) ** 2 for v in present) / len(present)
    return Stat(mean, math.sqrt(var), len(present), across)


def _across(by: str, groups: Sequence[GroupMetrics]) -> AcrossGroups:
    label = f"{by}s"
    et = _spread((g.et.mean for g in groups), label)
    full = _spread((g.fully_traceable_share.mean for g in groups), label)
    etp = _spread((g.et_partial.mean for g in groups), label)
    empty = Stat(0.0, 0.0, 0, label)
    return AcrossGroups(
        by=by,
        groups=len(groups),
        et=et or empty,
        fully_traceable_share=full or empty,
        et_partial=etp or empty,
        tc=_spread((g.tc for g in groups), label),
        dr=_spread((g.dr for g in groups), label),
    )


def _metric_value(name: str, g: GroupMetrics) -> float | None:
    if g.decisions == 0 and name != "TC":
        return None
    return {
        "ET": g.et.mean,
        "ET_full": g.fully_traceable_share.mean,
        "ET_partial": g.et_partial.mean,
        "TC": g.tc,
        "DR": g.dr,
        "TCS": g.tcs.mean,
    }[name]


def _check(name: str, threshold: float, overall: GroupMetrics) -> ThresholdCheck:
    value = _metric_value(name, overall)
    # A metric that cannot be computed (no decisions, no interval) does not pass a threshold.
    return ThresholdCheck(name, threshold, value, value is not None and value >= threshold)


_HAS_CHANNELS = b'"channels":[{'
"""Execution records with channels contain this (compact JSON, PROFILE §6); the others,
every profile 1.0 record among them, are not parsed again for it."""


def _may_cite_recording(perception: bytes | None) -> bool:
    """False only when the stored perception message cannot hold a ``recording`` key: the
    word is not in its bytes and no escape (a backslash) could spell it otherwise. Most logs
    cite no external recording, and two byte searches cost a fraction of walking every
    entity's evidence to find that out. (None: a warm summary cycle, whose parsed layer is
    walked.) A backslash, not ``\\u``: one byte is found by memchr, a pair is not."""
    return perception is None or b"recording" in perception or b"\\" in perception


def _add_channels(into: dict[tuple[str, str], list[float]], execution: Any) -> None:
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


def _channel_deviation(
    channels: dict[tuple[str, str], list[float]],
) -> tuple[ChannelDeviation, ...]:
    return tuple(
        ChannelDeviation(
            name=name,
            unit=unit,
            cycles=int(n),
            logged=int(logged),
            mean=total / logged if logged else None,
            max=top if logged else None,
        )
        for (name, unit), (n, logged, total, top) in sorted(channels.items())
    )


def _logging_cost(entries: list[tuple[float, int, CostHistogram | None]]) -> LoggingCost | None:
    weight = sum(n for _, n, _ in entries)
    if not entries or weight <= 0:
        return None
    mean_ns = sum(m * n for m, n, _ in entries) / weight
    merged: CostHistogram | None = CostHistogram()
    for _, _, histogram in entries:
        if histogram is None or merged is None:
            merged = None  # percentiles of some segments would not describe the others
        else:
            merged.merge(histogram)
    return LoggingCost(
        cycles=weight,
        segments=len(entries),
        mean_ns=mean_ns,
        p50_ns=merged.percentile_ns(0.5) if merged else None,
        p99_ns=merged.percentile_ns(0.99) if merged else None,
        max_ns=merged.max_ns if merged else None,
    )


def _timing(cost: LoggingCost | None) -> str:
    if cost is None:
        return "not logged"
    text = f"{cost.mean_ns / 1e6:.3f} ms mean per cycle"
    if cost.p50_ns is not None and cost.p99_ns is not None:
        text += f", p50 {cost.p50_ns / 1e6:.3f} ms, p99 {cost.p99_ns / 1e6:.3f} ms"
    return f"{text} ({TIMING_METADATA} metadata, {cost.cycles} cycles)"


def _definitions(cfg: MetricsConfig) -> dict[str, str]:
    w = cfg.weights
    return {
        "decision": "every cycle in the log (sealed, or an unsealed tail of a crashed writer)",
        "ET": "share of the action's factors with a documented chain to a resolving sensor "
        "reading; 0 when the action or its factors are missing",
        "chain": "factor node -> belief path (edges child->parent) -> entity node -> "
        "perception entity -> evidence ref -> logged sensor message",
        "expected_depth": f"{EXPECTED_DEPTH_STATE} for a factor on a derived-state node, "
        f"{EXPECTED_DEPTH_ENTITY} for a factor on an entity node",
        "ET_partial": "mean over factors of documented depth / expected depth",
        "sensor_window": f"refs resolve against the decision's cycle and the "
        f"{cfg.sensor_window} cycles before it (topic, log time, sequence, "
        "sha256)",
        "TC": f"1 - sum(gaps) / window per robot; a gap is an interval between sealed cycles "
        f"longer than (1 + {cfg.gap_tolerance:g}) x the nominal period, counted as the "
        "time beyond one period; window = last - first sealed time + one period",
        "DR": "action logged x >= 1 alternative logged x rationale complete (not truncated, "
        "factors present, counterfactuals present or none-applicable)",
        "integrity": "sealed, every layer matches its seal digest, no named layer missing, "
        "seal prev = digest of the previous seal",
        "TCS": f"({w.et:g} ET + {w.et_partial:g} ET_partial + {w.dr:g} DR + "
        f"{w.continuity:g} continuity + {w.integrity:g} integrity) / "
        f"{w.et + w.et_partial + w.dr + w.continuity + w.integrity:g}"
        + ("; 0 when integrity fails" if w.integrity_gate else ""),
        "std": "population std (ddof=0); each value says whether it is across decisions or "
        "across groups",
    }


# --- small parsing helpers ---------------------------------------------------------------------


def _items(text: str) -> Iterator[str]:
    for raw in text.split(","):
        item = raw.strip()
        if item:
            yield item


def _split_pair(item: str, what: str) -> tuple[str, str]:
    if "=" not in item:
        raise UsageError(f"{what} {item!r} is not NAME=VALUE")
    key, value = item.split("=", 1)
    return key.strip(), value.strip()


def _number(text: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError as err:
        raise UsageError(f"{what}: {text!r} is not a number") from err
    if not math.isfinite(value):
        raise UsageError(f"{what}: {text!r} is not a finite number")
    return value
