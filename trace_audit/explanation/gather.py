"""Which decision ``explain`` is asked about, and everything gathered about it: its chains,
graph and tree, what the walk back found, its seal and its scores, in one ``Explanation``."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from trace_audit.causal import causal_graph_data, read_decision, tree_graph_data
from trace_audit.chains import DEFAULT_SENSOR_WINDOW, DecisionChains, SensorWindow, trace_cycle
from trace_audit.evidence import (
    ExternalEvidence,
    describe_channel_refs,
    describe_refs,
    recordings_for,
)
from trace_audit.explanation.look_back import LookBack, look_back
from trace_audit.explanation.result import Explanation
from trace_audit.explanation.scores import decision_scores
from trace_audit.explanation.seal import check_seal
from trace_audit.log_source import LogSource, as_log, require_cycles
from trace_audit.log_time import LogClock, TimeArg
from trace_audit.selection import Selection, robot_at, robot_with_cycle
from trace_audit.sensor_health import SensorHealth, sensor_health
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.errors import StaleCatalogError, TimeOutOfRangeError, UsageError
from trace_runtime.reading.logset import Log
from trace_runtime.reading.reader import Segment
from trace_runtime.reading.recordings import Recordings
from trace_runtime.records import TOPIC_EXECUTION, TOPIC_PERCEPTION

__all__ = ["DEFAULT_LOOKBACK_S", "explain", "find_cycle"]

DEFAULT_LOOKBACK_S = 600.0


def find_cycle(log: Log, number: int) -> Cycle:
    """The cycle with this number: a binary search over time through ``Log.cycle_at``."""
    lo, hi = log.start_ns, log.end_ns
    first: Cycle | None = None
    while lo <= hi:
        mid = (lo + hi) // 2
        try:
            found = log.cycle_at(mid)
        except TimeOutOfRangeError:
            lo = mid + 1
            continue
        if found.cycle == number:
            return found
        if found.cycle < number:
            lo = mid + 1
        else:
            hi = mid - 1
        first = first or found
    # Cycle numbers follow time only within one run of the robot's clock: after a restart
    # with a monotonic clock the search above can miss, and a scan bounded by each
    # segment's first cycle finds it.
    found_by_scan = log.get_cycle(number)
    if found_by_scan is not None:
        return found_by_scan
    last = next(log.iter_cycles(reverse=True), None)
    oldest = next(log.iter_cycles(), None)
    span = f"cycles {oldest.cycle}..{last.cycle}" if oldest and last else "no cycles"
    raise UsageError(f"cycle {number} is not in this log ({span})")


def explain(
    source: LogSource,
    *,
    t: TimeArg = None,
    cycle: int | None = None,
    lookback_s: float = DEFAULT_LOOKBACK_S,
    sensor_window: int = DEFAULT_SENSOR_WINDOW,
    evidence: Sequence[str | Path] = (),
    robots: Sequence[str] = (),
    recordings: Recordings | None = None,
) -> Explanation:
    """Explain the decision in force at ``t`` (or cycle number ``cycle``) in a log.

    ``evidence``: external recordings (MCAP files, rosbag2 directories) whose messages the
    decision's evidence refs may name; they are resolved, digest-checked and decoded.
    ``recordings``: a caller's one resolution of evidence (the incident report's), used
    instead of resolving the log's declared recordings and ``evidence`` here.
    ``robots``: look only at these robots' decisions. On a log of several robots the time
    (or cycle number) must name one robot's decision (``selection.robot_at``): otherwise
    ``SeveralRobotsError`` names the robots that have one."""
    if (t is None) == (cycle is None):
        raise UsageError("give exactly one of a time (--t) or a cycle number (--cycle)")
    if lookback_s < 0:
        raise UsageError(f"lookback must be >= 0 s, got {lookback_s}")

    def explain_in(log: Log) -> Explanation:
        return _explain(
            log,
            t=t,
            cycle=cycle,
            lookback_s=lookback_s,
            sensor_window=sensor_window,
            evidence=evidence,
            selection=Selection(tuple(robots)),
            recordings=recordings,
        )

    try:
        return explain_in(as_log(source, lazy=True))
    except StaleCatalogError:
        # The catalog is a hint: a row its file does not confirm is ignored, not obeyed.
        return explain_in(as_log(source))


def _explain(
    log: Log,
    *,
    t: TimeArg,
    cycle: int | None,
    lookback_s: float,
    sensor_window: int,
    evidence: Sequence[str | Path],
    selection: Selection,
    recordings: Recordings | None = None,
) -> Explanation:
    log = selection.of(log)
    require_cycles(log)
    t_ns, log, target, offset = _find_target(log, t, cycle)
    whole, log = log, log.clock_run(target.segment)
    decision = read_decision(target)
    holder = log.segment_named(target.segment)
    if recordings is None:
        # its own segment's (whose logger wrote the refs): not every one, opened lazily
        recordings = recordings_for([holder] if holder is not None else whole, evidence)
    period, clock = _cadence(holder, log, whole)
    chains, back = _chains_and_back(
        log,
        target,
        decision.command,
        recordings,
        lookback_ns=int(lookback_s * 1e9),
        sensor_window=sensor_window,
        period_ns=period,
    )
    seal = check_seal(log, target, back.prev_sealed)
    scores = decision_scores(target, chains, seal, prev_sealed=back.prev_sealed, period_ns=period)
    graph = causal_graph_data(target, chains, decision, LogClock(clock, whole.start_ns))
    external, channels, sensors = _readings(target, recordings, period)
    return Explanation(
        path=str(whole.root),
        robot=log.first_robot,
        log_start_ns=whole.start_ns,
        log_end_ns=whole.end_ns,
        clock=clock,
        recovered=whole.recovered,
        live=whole.live or None,
        query_t_ns=t_ns,
        query_cycle=cycle,
        cycle=target.cycle,
        t_ns=target.t_ns,
        offset_ns=offset,
        period_ns=period,
        decision=decision,
        chains=chains,
        scores=scores,
        seal=seal,
        held=back.held,
        graph=graph,
        tree=tree_graph_data(decision.tree) if decision.tree else None,
        external_evidence=external,
        clock_run=() if log is whole else tuple(s.path.name for s in log.segments),
        channel_evidence=channels,
        sensors=sensors,
    )


def _cadence(holder: Segment | None, log: Log, whole: Log) -> tuple[int, str]:
    """The period and clock the robot kept when it decided: those of the segment holding
    the decision (the walk back, the gap to the previous seal and the output use them)."""
    if holder is None:
        return log.period_ns, whole.clock
    return holder.session.period_ns, holder.session.clock


def _readings(
    target: Cycle, recordings: Recordings | None, period_ns: int
) -> tuple[tuple[ExternalEvidence, ...], tuple[ExternalEvidence, ...], SensorHealth]:
    """The decision's evidence in recordings, the messages its actuator channels were read
    from, and what it knew about its sensors (used, unavailable, the age of each reading)."""
    perception = target.layer(TOPIC_PERCEPTION)
    execution = target.layer(TOPIC_EXECUTION)
    return (
        tuple(describe_refs(perception, recordings)),
        tuple(describe_channel_refs(execution, recordings, target.sensors)),
        sensor_health(perception, execution, target.t_ns, period_ns),
    )


def _find_target(log: Log, t: TimeArg, cycle: int | None) -> tuple[int | None, Log, Cycle, int]:
    """(the query time in ns or None, the log of the robot that decided, the decision in
    force then or with that number, the query time - decision time)."""
    if t is not None:
        log, t_ns = robot_at(log, t)
        target = log.cycle_at(t_ns)
        return t_ns, log, target, t_ns - target.t_ns
    assert cycle is not None
    log, target = robot_with_cycle(log, cycle, find_cycle)
    return None, log, target, 0


def _chains_and_back(
    log: Log,
    target: Cycle,
    command: str | None,
    recordings: Recordings | None,
    *,
    lookback_ns: int,
    sensor_window: int,
    period_ns: int,
) -> tuple[DecisionChains, LookBack]:
    """The decision's chains, and what one walk back from it found.

    Refs usually point into the decision's own cycle; the earlier cycles of the sensor
    window are read only when a chain stops at an unresolved reading (same result as
    resolving against the whole window, as the metrics do)."""
    chains = trace_cycle(target, recordings=recordings)
    needs_window = sensor_window > 0 and any(
        c.missing is not None and c.missing.level == "sensor_reading" for c in chains.factors
    )
    back = look_back(
        log,
        target,
        command,
        lookback_ns,
        sensor_window if needs_window else 0,
        period_ns=period_ns,
    )
    if needs_window:
        chains = _trace_in_window(target, back.window, SensorWindow(sensor_window, recordings))
    return chains, back


def _trace_in_window(target: Cycle, earlier: list[Cycle], window: SensorWindow) -> DecisionChains:
    """The decision's chains with refs resolved against the cycles before it (newest first
    in ``earlier``) and its own."""
    for cycle in reversed(earlier):
        window.push(cycle.sensors)
    window.push(target.sensors)
    return trace_cycle(target, window)
