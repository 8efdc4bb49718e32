"""The scan: one robot's segments read in chain order, each decision scored into its group.

A ``_Scanner`` carries what crosses a segment boundary (the sensor window for evidence refs,
the last seal for the hash chain, the last sealed time for gaps and the clock's runs), so a
robot's segments scored one by one (``score_segment``, after ``prefill`` from the tail of
the previous segment) come out as in one pass (``score_robot``).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

from trace_audit.chains import DecisionScore, SensorWindow, score_layers, trace_layers
from trace_audit.evidence import recordings_for
from trace_audit.log_time import hour_of
from trace_audit.metrics.config import MetricsConfig
from trace_audit.metrics.decision import (
    dr_problems,
    et_problems,
    integrity_problems,
    scenario_of,
    trust_score,
)
from trace_audit.metrics.results import DecisionFailure
from trace_audit.metrics.sums import (
    HAS_CHANNELS,
    MAY_FAIL_A_CHECK,
    DecisionSink,
    GroupSums,
    ScanResult,
    ScoredDecision,
    SealOutcome,
    add_channels,
    add_failed_checks,
)
from trace_runtime.chain import digest
from trace_runtime.clock import clock_restarted, is_wall_clock
from trace_runtime.costs import TIMING_METADATA, CostHistogram
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.encoding.partial import (
    INDEX_ACTION,
    INDEX_BELIEF,
    INDEX_PERCEPTION,
    METRICS_ACTION,
    METRICS_BELIEF,
    METRICS_PERCEPTION,
    read_layer,
)
from trace_runtime.encoding.seal_check import verify_cycle
from trace_runtime.gaps import Gap, continuity, find_gap
from trace_runtime.reading.reader import Segment, open_segment
from trace_runtime.reading.recordings import Recordings
from trace_runtime.records import (
    TOPIC_ACTION,
    TOPIC_BELIEF,
    TOPIC_EXECUTION,
    TOPIC_PERCEPTION,
    TOPIC_SEAL,
)

__all__ = ["score_robot", "score_segment"]

_PROGRESS_EVERY = 2048


@dataclass(slots=True)
class _Stream:
    """Where one robot's sealed sequence stands: the last sealed time and seal digest."""

    prev_t_ns: int | None = None
    prev_cycle: int = -1
    prev_seal: str | None = None
    prev_segment: str = ""
    """The file the last sealed cycle came from."""


class _Interval(NamedTuple):
    """What the interval a sealed cycle closes adds to TC: continuity, window, gap."""

    continuity: float
    window_ns: int
    gap: Gap | None
    clock_anomaly: bool


class _Scanner:
    """Scores the cycles of one robot's segments in order, carrying chain and window state."""

    def __init__(
        self,
        config: MetricsConfig,
        partial: ScanResult,
        recordings: Recordings | None,
        sink: DecisionSink | None = None,
    ) -> None:
        self.config = config
        self.partial = partial
        self.sink = sink
        self.shapes = _METRICS_SHAPES if sink is None else _INDEX_SHAPES
        self.window = SensorWindow(config.sensor_window, recordings)
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
        self._add_timing(segment, done)

    def _add_timing(self, segment: Segment, cycles: int) -> None:
        """Keep the logger's own cost per cycle when the segment's writer measured it."""
        timing = segment.metadata.get(TIMING_METADATA)
        if timing:
            with contextlib.suppress(KeyError, ValueError):  # a malformed record: not timed
                self.partial.timing.append(
                    (
                        float(timing["commit_mean_ns"]),
                        int(timing.get("cycles", cycles)),
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
        wall = is_wall_clock(segment.session.clock, segment.info.start_ns)
        return lambda cycle: hour_of(cycle.t_ns, wall)

    def _count_external(self, perception: object) -> None:
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
                    check = self.window.check_external(ref)
                    tally[check.state] = tally.get(check.state, 0) + 1
                    if check.state == "unresolved":
                        self.partial.unread.setdefault(check.recording, check.detail)

    def _score(self, cycle: Cycle, segment: Segment, group_of: Callable[[Cycle], str]) -> None:
        """Score one decision into its group's sums; list it when it fails."""
        window = self.window
        window.push(cycle.sensors)
        # Each layer is read once: ET, DR, the seal check's evidence step and a sink (the
        # fleet index's rows) share it, only the fields they read decoded
        # (trace_runtime.encoding.partial): the index's shapes are the metrics' and its columns.
        action_shape, belief_shape, perception_shape = self.shapes
        action = read_layer(cycle, action_shape)
        belief = read_layer(cycle, belief_shape)
        perception = read_layer(cycle, perception_shape)
        score = score_layers(action, belief, perception, window=window)
        if perception is not None and _may_cite_recording(cycle.payloads.get(TOPIC_PERCEPTION)):
            self._count_external(perception)
        missing_dr = dr_problems(action)
        self._add_execution(cycle, segment)
        group = group_of(cycle)
        partial = self.partial
        acc = partial.groups.get(group)
        if acc is None:
            acc = partial.groups[group] = GroupSums()
        seal = self._seal_and_gap(cycle, segment, acc, perception)
        tcs = self._add_scores(acc, cycle, score, dr_ok=not missing_dr, seal=seal)
        if self.sink is not None:
            self.sink(
                ScoredDecision(
                    cycle,
                    segment,
                    group,
                    action,
                    belief,
                    perception,
                    cycle.layer(TOPIC_EXECUTION),
                    score,
                    tuple(missing_dr),
                    seal,
                    tcs,
                )
            )
        # a decision whose ET is unknown fails only what is known to fail (DR, integrity)
        full = score.unknown > 0 or (score.factors > 0 and score.traceable == score.factors)
        if full and not missing_dr and not seal.problems:
            return
        partial.failures_total += 1
        if len(partial.failures) < self.config.max_listed:
            partial.failures.append(
                self._listed_failure(cycle, segment, group, score, dr=missing_dr, seal=seal)
            )

    def _listed_failure(
        self,
        cycle: Cycle,
        segment: Segment,
        group: str,
        score: DecisionScore,
        *,
        dr: list[str],
        seal: SealOutcome,
    ) -> DecisionFailure:
        """A failing decision as listed; a chain that is not fully traceable is walked again
        with its links, since a listed chain names factors and nodes (the whole layers)."""
        problems: tuple[str, ...] | list[str] = ()
        if not score.fully_traceable:
            problems = et_problems(
                trace_layers(
                    cycle.cycle,
                    cycle.t_ns,
                    cycle.layer(TOPIC_ACTION),
                    cycle.layer(TOPIC_BELIEF),
                    cycle.layer(TOPIC_PERCEPTION),
                    window=self.window,
                )
            )
        return DecisionFailure(  # its problems prefixed by the metric they fail
            cycle.cycle,
            cycle.t_ns,
            segment.path.name,
            group,
            score.et if score.known else None,
            score.et_partial if score.known else None,
            (*problems, *(f"DR: {p}" for p in dr), *(f"integrity: {p}" for p in seal.problems)),
        )

    def _add_execution(self, cycle: Cycle, segment: Segment) -> None:
        """Add the execution record's actuator channels and failed checks to the sums; the
        record is parsed only when its bytes show it may hold either."""
        partial = self.partial
        data = cycle.payloads.get(TOPIC_EXECUTION)
        if data is None:
            if cycle.summary is not None:  # warm keeps execution whole
                execution = cycle.summary.get(TOPIC_EXECUTION)
                add_channels(partial.channels, execution)
                add_failed_checks(partial.checks, execution, segment.session.robot_id, cycle)
            return
        channels, may_fail = HAS_CHANNELS in data, MAY_FAIL_A_CHECK in data
        if not (channels or may_fail):
            return
        execution = cycle.layer(TOPIC_EXECUTION)
        if channels:
            add_channels(partial.channels, execution)
        if may_fail:
            add_failed_checks(partial.checks, execution, segment.session.robot_id, cycle)

    def _add_scores(
        self, acc: GroupSums, cycle: Cycle, score: DecisionScore, *, dr_ok: bool, seal: SealOutcome
    ) -> float | None:
        """Add the decision's ET, ET_partial, DR, integrity and TCS(d) to its group's sums;
        return its TCS(d). A decision whose ET is unknown adds to DR and integrity only, and
        is counted apart: its TCS is unknown (None), never a number made of a guess."""
        et, etp = score.et, score.et_partial
        factors, traceable = score.factors, score.traceable
        intact = not seal.problems
        acc.decisions += 1
        if cycle.summary is not None:
            acc.summarized += 1
        acc.dr_ok += dr_ok
        acc.integrity_ok += intact
        if score.unknown:
            acc.unknown += 1
            return None
        acc.et_sum += et
        acc.et_sq += et * et
        acc.etp_sum += etp
        acc.etp_sq += etp * etp
        acc.full += factors > 0 and traceable == factors
        acc.factors += factors
        acc.factors_traceable += traceable
        acc.no_factors += factors == 0
        tcs = trust_score(
            self.config.weights,
            et=et,
            et_partial=etp,
            dr_ok=dr_ok,
            continuity=seal.continuity,
            intact=intact,
        )
        acc.tcs_sum += tcs
        acc.tcs_sq += tcs * tcs
        return tcs

    def _seal_and_gap(
        self, cycle: Cycle, segment: Segment, acc: GroupSums, perception: object
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
        if status.state in _UNVOUCHED:
            _parse_in_full(cycle)
        if status.state == "unsealed":
            return SealOutcome(integrity, False, 0.0, 0, None, 0, False)
        acc.sealed += 1
        stream.prev_seal = status.seal_digest
        acc.dropped += status.dropped
        interval = self._close_interval(cycle, segment, acc, status.dropped)
        stream.prev_t_ns = cycle.t_ns
        stream.prev_cycle = cycle.cycle
        stream.prev_segment = segment.path.name
        return SealOutcome(
            integrity,
            True,
            interval.continuity,
            interval.window_ns,
            interval.gap,
            status.dropped,
            interval.clock_anomaly,
        )

    def _close_interval(
        self, cycle: Cycle, segment: Segment, acc: GroupSums, dropped: int
    ) -> _Interval:
        """The interval from the robot's previous sealed cycle to this one, into TC's sums.

        The first sealed cycle, and the first after the clock restarted between segments
        (``trace_runtime.clock``), opens a window of one period; a time that does not move
        on within a run is a clock anomaly (no interval); any other interval is judged by
        the one gap rule."""
        stream = self.stream
        period = segment.session.period_ns
        prev_t, t_ns = stream.prev_t_ns, cycle.t_ns
        restart = (
            prev_t is not None
            and stream.prev_segment not in ("", segment.path.name)
            and clock_restarted(prev_t, t_ns)
        )
        if prev_t is None or restart:
            acc.window_ns += period
            acc.restarts += restart
            return _Interval(1.0, period, None, False)
        if t_ns <= prev_t:
            acc.anomalies += 1
            return _Interval(1.0, 0, None, True)
        interval = t_ns - prev_t
        acc.window_ns += interval
        gap = find_gap(
            stream.prev_cycle,
            prev_t,
            cycle.cycle,
            t_ns,
            period,
            tolerance=self.config.gap_tolerance,
            declared_dropped=dropped,
            robot=segment.session.robot_id,
        )
        if gap is None:
            return _Interval(1.0, interval, None, False)
        acc.gap_ns += gap.gap_ns
        acc.gaps += 1
        acc.missing_cycles += gap.missing_cycles
        self.partial.gaps_total += 1
        if len(self.partial.gaps) < self.config.max_listed:
            self.partial.gaps.append(gap)
        return _Interval(
            continuity(interval, period, self.config.gap_tolerance), interval, gap, False
        )

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


_METRICS_SHAPES = (METRICS_ACTION, METRICS_BELIEF, METRICS_PERCEPTION)
_INDEX_SHAPES = (INDEX_ACTION, INDEX_BELIEF, INDEX_PERCEPTION)
"""What a scan decodes of a cycle's action, belief and perception: the index's shapes hold
the metrics' fields and the columns of its rows (``fleet.rows``)."""

_UNVOUCHED = ("modified", "unsealed")
"""Seal states in which the seal does not vouch for a cycle's layer bytes."""


def _parse_in_full(cycle: Cycle) -> None:
    """Parse the layers metrics read in full, in the order metrics read them, for the error
    a message orjson refuses raises (``PayloadError``). The partial decode checks the syntax
    of every byte but not the range of a number it skips (orjson refuses ``1e400``): where
    the seal does not vouch for the bytes (damage, a crash's unsealed tail) this parse makes
    such a message fail as it always did. Its values are not used: where both decodes
    succeed, the partial one is this one's restricted to the keys metrics read."""
    for topic in (TOPIC_ACTION, TOPIC_BELIEF, TOPIC_PERCEPTION):
        cycle.layer(topic)


def _may_cite_recording(perception: bytes | None) -> bool:
    """False only when the stored perception message cannot hold a ``recording`` key whose
    value is a string (the only refs the tally counts): every ``recording`` in its bytes is
    the key of a ``"recording":null`` and no escape (a backslash) could spell the word, or
    a quote, otherwise. Most logs cite no external recording, and a writer may still give
    every ref ``"recording":null``; two byte counts cost a fraction of walking every
    entity's evidence to find that out. (None: a warm summary cycle, whose parsed layer is
    walked.) A backslash, not ``\\u``: one byte is found by memchr, a pair is not."""
    return (
        perception is None
        or b"\\" in perception
        or perception.count(b"recording") != perception.count(b'"recording":null')
    )


def score_segment(
    path: str | Path,
    previous: str | Path | None,
    config: MetricsConfig,
    sink: DecisionSink | None = None,
    recordings: Recordings | None = None,
) -> ScanResult:
    """Score one segment as a run over the whole log would: the tail of the robot's
    ``previous`` segment is read first, so chain links, gaps and refs across the boundary
    come out the same. Each decision is also handed to ``sink`` (the fleet index).
    ``recordings``: the log's one resolution of evidence; None: resolved here, from what
    the segments declare and ``config.evidence`` (``evidence.recordings_for``)."""
    partial = ScanResult()
    segment = open_segment(path)
    before = open_segment(previous) if previous is not None else None
    if recordings is None:
        scanned = [segment] if before is None else [before, segment]
        recordings = recordings_for(scanned, config.evidence)
    scanner = _Scanner(config, partial, recordings, sink)
    if before is not None:
        scanner.prefill(before)
    scanner.scan(segment)
    return partial


def score_robot(
    segments: Sequence[Segment],
    config: MetricsConfig,
    progress: Callable[[int], None] | None = None,
    recordings: Recordings | None = None,
) -> ScanResult:
    """Score one robot's segments in chain order in this process, in one pass (evidence
    resolved as ``score_segment`` says)."""
    partial = ScanResult()
    if recordings is None:
        recordings = recordings_for(segments, config.evidence)
    scanner = _Scanner(config, partial, recordings)
    for segment in segments:
        scanner.scan(segment, progress)
    return partial
