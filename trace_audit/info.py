"""What a log is: robot, time range, cycles, segments and tiers, channels, drops and gaps.

The header facts (segments, tiers, time ranges, channel counts) come from each segment's
summary, so they cost the same for a minute or a day of log. Dropped cycles (the sum of the
seals' ``dropped``) and gaps in time need every seal: ``log_info(scan=True)`` (the default)
reads them all; ``scan=False`` answers from the summaries alone and says so.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from trace_audit.cycle_fields import seal_dropped
from trace_audit.jsonout import OMIT_EMPTY
from trace_audit.log_gaps import gap_stepper
from trace_audit.log_source import LogSource, as_log, require_cycles
from trace_audit.log_time import SECONDS_CLOCK, LogClock
from trace_audit.selection import Selection
from trace_runtime.clock import ClockStep
from trace_runtime.gaps import DEFAULT_GAP_TOLERANCE, CycleRange, Gap
from trace_runtime.logger.chain_writer import CLOSE_METADATA
from trace_runtime.reading.logset import Log
from trace_runtime.reading.reader import Segment
from trace_runtime.records import TOPIC_SEAL

__all__ = ["LogInfo", "SegmentRow", "log_info"]


@dataclass(frozen=True, slots=True)
class SegmentRow:
    """One segment file of the log."""

    path: str
    tier: str
    robot: str
    segment: int
    start_ns: int
    end_ns: int
    first_cycle: int | None
    last_cycle: int | None
    cycles: int
    bytes: int
    chunks: int
    finished: bool
    recovered: bool
    live: bool
    software_version: str
    policy_version: str


@dataclass(frozen=True, slots=True)
class LogInfo:
    """A log at a glance. ``scanned`` says whether drops and gaps were counted."""

    path: str
    robots: tuple[str, ...]
    start_ns: int
    end_ns: int
    period_ns: int
    cycles: int
    segments: tuple[SegmentRow, ...]
    tiers: dict[str, int]
    channels: dict[str, int]
    finished: bool
    recovered: bool
    live: bool
    scanned: bool
    dropped: int | None
    gaps: tuple[Gap, ...]
    """Gaps between each robot's sealed cycles, by the rule metrics uses for TC."""
    clock: LogClock = SECONDS_CLOCK
    """The log's clock and first time: how its times are shown (``log_time.LogClock``)."""
    clock_steps: tuple[ClockStep, ...] = field(default=(), metadata={OMIT_EMPTY: True})
    """Where a robot's clock went back between segments: a step its writer declared, or a
    restart (``Log.clock_steps``); each run of the clock is read apart."""

    @property
    def duration_ns(self) -> int:
        return self.end_ns - self.start_ns

    @property
    def gap_ns(self) -> int:
        """Time in gaps beyond the nominal period (what temporal continuity counts as lost)."""
        return sum(g.gap_ns for g in self.gaps)


def log_info(
    source: LogSource,
    *,
    scan: bool = True,
    gap_tolerance: float = DEFAULT_GAP_TOLERANCE,
    robots: Sequence[str] = (),
) -> LogInfo:
    """Describe a log (``robots``: only these robots' segments); ``scan`` reads every seal to
    count dropped cycles and gaps. The CLI describes each robot of a root on its own
    (``selection.per_robot``)."""
    log = Selection(tuple(robots)).of(as_log(source))
    require_cycles(log)
    period = max((s.session.period_ns for s in log.segments), default=0)
    seen = _scan_seals(log, gap_tolerance) if scan else _Scanned({}, {}, None, [])
    rows: list[SegmentRow] = []
    channels: dict[str, int] = {}
    tiers: dict[str, int] = {}
    for segment in log.segments:
        info = segment.info
        if not scan:
            _from_summary(segment, seen)
        for topic, n in info.channels.items():
            channels[topic] = channels.get(topic, 0) + n
        tiers[info.tier] = tiers.get(info.tier, 0) + 1
        name = segment.path.name
        rows.append(_segment_row(segment, seen.ranges.get(name), seen.counts.get(name, 0)))
    return LogInfo(
        path=str(log.root),
        robots=tuple(dict.fromkeys(s.session.robot_id for s in log.segments)),
        start_ns=log.start_ns,
        end_ns=log.end_ns,
        period_ns=period,
        cycles=sum(r.cycles for r in rows),
        segments=tuple(rows),
        tiers=tiers,
        channels=dict(sorted(channels.items())),
        finished=all(r.finished for r in rows),
        recovered=log.recovered,
        live=log.live,
        scanned=scan,
        dropped=seen.dropped,
        gaps=tuple(seen.gaps),
        clock=LogClock.of(log),
        clock_steps=tuple(log.clock_steps()),
    )


@dataclass(slots=True)
class _Scanned:
    """Per segment file: cycles and their range; for the log: drops (None unscanned), gaps."""

    counts: dict[str, int]
    ranges: dict[str, CycleRange]
    dropped: int | None
    gaps: list[Gap]


def _scan_seals(log: Log, gap_tolerance: float) -> _Scanned:
    """Every cycle read once: each segment's cycles and range, the drops, the gaps."""
    out = _Scanned({}, {}, 0, [])
    dropped = 0
    gap_of = gap_stepper(log, gap_tolerance)
    for cycle in log.iter_cycles():
        name = cycle.segment
        out.counts[name] = out.counts.get(name, 0) + 1
        out.ranges[name] = CycleRange.of(cycle.cycle, cycle.t_ns).merge(out.ranges.get(name))
        dropped += seal_dropped(cycle)
        gap = gap_of(cycle)
        if gap is not None:
            out.gaps.append(gap)
    # Drops after a segment's last seal are declared at close, not by a seal.
    out.dropped = dropped + sum(_dropped_at_close(s) for s in log.segments)
    return out


def _from_summary(segment: Segment, into: _Scanned) -> None:
    """A segment's cycles from its summary, and its range up to its newest cycle."""
    info = segment.info
    name = segment.path.name
    into.counts[name] = info.channels.get(TOPIC_SEAL, 0)
    newest = next(segment.iter_cycles(reverse=True), None)
    if newest is not None:
        into.ranges[name] = CycleRange(
            segment.session.first_cycle, newest.cycle, info.start_ns, newest.t_ns
        )


def _segment_row(segment: Segment, cycles: CycleRange | None, count: int) -> SegmentRow:
    info = segment.info
    return SegmentRow(
        path=str(segment.path),
        tier=info.tier,
        robot=segment.session.robot_id,
        segment=segment.session.segment,
        start_ns=info.start_ns,
        end_ns=info.end_ns,
        first_cycle=None if cycles is None else cycles.first_cycle,
        last_cycle=None if cycles is None else cycles.last_cycle,
        cycles=count,
        bytes=info.bytes,
        chunks=info.chunk_count,
        finished=info.finished,
        recovered=info.recovered,
        live=info.live,
        software_version=segment.session.software_version,
        policy_version=segment.session.policy_version,
    )


def _dropped_at_close(segment: Segment) -> int:
    closing = segment.metadata.get(CLOSE_METADATA, {})
    try:
        return int(closing.get("dropped_after_last_seal", 0))
    except ValueError:
        return 0
