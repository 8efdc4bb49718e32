"""Explain one decision: what the robot did at t, why, what else it weighed, and can we trust it.

``explain(log, t=...)`` finds the decision in force at ``t`` (the last cycle at or before it,
through the segment's chunk index: one chunk is decoded, however long the log) and gathers:
the action and its rationale, factors, alternatives and why each lost, counterfactuals, the
counterfactual decision tree with the taken path, every factor's causal chain down to the
sensor reading (each link documented or not), the causal graph, the execution record, this
decision's ET / ET_partial (and DR / TCS from the metrics library), whether its seal
verifies, and since when the action has held.

Looking back is bounded: one reverse walk from the decision, at most ``lookback_s`` of log
time, finds the previous seal (for the hash chain), the sensor readings of the cycles before
(evidence refs may point at them), and the cycle where the current action began. When the
walk reaches the bound first, the action has held "at least since" the oldest cycle seen.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from trace_audit.causal import Decision, causal_graph_data, read_decision, tree_graph_data
from trace_audit.chains import DEFAULT_SENSOR_WINDOW, DecisionChains, SensorWindow, trace_cycle
from trace_audit.cycle_fields import command_of
from trace_audit.evidence import ExternalEvidence, describe_refs, open_recordings
from trace_audit.jsonout import OMIT_EMPTY
from trace_audit.log_source import LogSource, as_log, require_cycles
from trace_audit.log_time import LogClock, TimeArg
from trace_audit.metrics import MetricsConfig, dr_problems, trust_score
from trace_audit.selection import Selection, robot_at, robot_with_cycle
from trace_runtime.chain import GENESIS, digest
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.encoding.seal_check import verify_cycle
from trace_runtime.errors import StaleCatalogError, TimeOutOfRangeError, UsageError
from trace_runtime.gaps import continuity, gap_limit_ns
from trace_runtime.reading.logset import Log
from trace_runtime.reading.recordings import Recordings
from trace_runtime.records import TOPIC_ACTION, TOPIC_PERCEPTION, TOPIC_SEAL

__all__ = [
    "DEFAULT_LOOKBACK_S",
    "DecisionScores",
    "Explanation",
    "HeldSince",
    "SealCheck",
    "explain",
    "find_cycle",
]

DEFAULT_LOOKBACK_S = 600.0


@dataclass(frozen=True, slots=True)
class SealCheck:
    """Whether the decision's seal verifies: its digests, and its link to the previous seal.

    The check is ``trace_runtime.encoding.seal_check.verify_cycle`` (``state`` is its verdict: the
    layer messages and the evidenced sensor readings against the seal). ``prev_source`` says
    what the seal's ``prev`` was compared with: the previous sealed cycle in this log, the
    segment's recorded ``prev_seal`` (the previous segment is not in the log), or genesis.

    ``in_flight``: the cycle is the one the robot was writing when it was killed (layer
    messages after the last seal of a crashed segment, PROFILE §8). It is not verified (it
    was never sealed) but nothing failed: verify makes it a note, not a finding.
    """

    state: str
    sealed: bool
    digests_ok: bool | None
    mismatched: tuple[str, ...]
    unnamed: tuple[str, ...]
    absent: tuple[str, ...]
    summarised: tuple[str, ...]
    evidence_checked: int
    evidence_mismatch: tuple[str, ...]
    prev_ok: bool | None
    prev_cycle: int | None
    prev_source: str
    dropped_before: int
    verified: bool
    problems: tuple[str, ...]
    in_flight: bool = False


@dataclass(frozen=True, slots=True)
class HeldSince:
    """Since when the current command has held, and the cycle that began it.

    ``bound`` is ``change`` (the cycle before ``since_cycle`` had another command,
    ``previous``), ``lookback`` (the walk stopped at its bound: held at least since) or
    ``log_start`` (held since the first cycle of the log, perhaps longer).
    """

    command: str | None
    since_cycle: int
    since_t_ns: int
    cycles: int
    bound: Literal["change", "lookback", "log_start"]
    previous: str | None
    previous_cycle: int | None
    at_least: bool


@dataclass(frozen=True, slots=True)
class DecisionScores:
    """This decision's auditability scores and where they come from.

    ``et`` and ``et_partial`` come from the chain walker; ``dr`` and ``tcs`` from the metrics
    library's definitions (the same ones ``trace-audit metrics`` uses). ``problems`` lists
    why a score is below 1.
    """

    et: float
    et_partial: float
    fully_traceable: bool
    dr: float
    tcs: float
    problems: tuple[str, ...]
    source: str


@dataclass(frozen=True, slots=True)
class Explanation:
    """Everything ``trace-audit explain`` shows about one decision."""

    path: str
    robot: str
    log_start_ns: int
    log_end_ns: int
    clock: str
    """The clock behind the times (``SessionInfo.clock``; ``log_time.LogClock`` shows them)."""
    recovered: bool
    query_t_ns: int | None
    query_cycle: int | None
    cycle: int
    t_ns: int
    offset_ns: int
    """query time - decision time (0 when asked by cycle number)."""
    period_ns: int
    decision: Decision
    chains: DecisionChains
    scores: DecisionScores
    seal: SealCheck
    held: HeldSince
    graph: dict[str, Any]
    tree: dict[str, Any] | None
    external_evidence: tuple[ExternalEvidence, ...] = ()
    """The decision's evidence refs into external recordings: resolved (and decoded),
    broken, or unresolved (recording not given)."""
    clock_run: tuple[str, ...] = ()
    """When the robot's clock restarted in the log: the segments of the run that holds the
    decision (a time may name a decision in another run too); empty otherwise."""
    live: bool | None = field(default=None, metadata={OMIT_EMPTY: True})
    """True when a segment of the log is being written right now (its logger holds the
    lock); None otherwise, and then left out of the JSON."""

    @property
    def log_clock(self) -> LogClock:
        """How this log's times are shown (``log_time.LogClock``)."""
        return LogClock(self.clock, self.log_start_ns)

    @property
    def stale(self) -> bool:
        """True when the time from the decision to the query would be a gap (the one gap
        rule, ``trace_runtime.gaps``): no decision was logged when one was due."""
        return self.period_ns > 0 and self.offset_ns > gap_limit_ns(self.period_ns)


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
) -> Explanation:
    """Explain the decision in force at ``t`` (or cycle number ``cycle``) in a log.

    ``evidence``: external recordings (MCAP files, rosbag2 directories) whose messages the
    decision's evidence refs may name; they are resolved, digest-checked and decoded.
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
) -> Explanation:
    log = selection.of(log)
    require_cycles(log)
    t_ns, log, target, offset = _find_target(log, t, cycle)
    whole, log = log, log.clock_run(target.segment)
    decision = read_decision(target)
    recordings = open_recordings(evidence)
    # The cadence the robot kept when it decided: the period of the segment holding the
    # decision (the walk back, the gap to the previous seal and the output use it).
    holder = log.segment_named(target.segment)
    period = holder.session.period_ns if holder is not None else log.period_ns
    chains, back = _chains_and_back(
        log,
        target,
        decision.command,
        recordings,
        lookback_ns=int(lookback_s * 1e9),
        sensor_window=sensor_window,
        period_ns=period,
    )
    seal = _check_seal(log, target, back.prev_sealed)
    scores = _scores(target, chains, seal, prev_sealed=back.prev_sealed, period_ns=period)
    graph = causal_graph_data(target, chains, decision)
    tree = tree_graph_data(decision.tree) if decision.tree else None
    return Explanation(
        path=str(whole.root),
        robot=log.first_robot,
        log_start_ns=whole.start_ns,
        log_end_ns=whole.end_ns,
        clock=holder.session.clock if holder is not None else whole.clock,
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
        tree=tree,
        external_evidence=tuple(describe_refs(target.layer(TOPIC_PERCEPTION), recordings)),
        clock_run=() if log is whole else tuple(s.path.name for s in log.segments),
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
) -> tuple[DecisionChains, _Back]:
    """The decision's chains, and what one walk back from it found.

    Refs usually point into the decision's own cycle; the earlier cycles of the sensor
    window are read only when a chain stops at an unresolved reading (same result as
    resolving against the whole window, as the metrics do)."""
    chains = trace_cycle(target, recordings=recordings)
    needs_window = sensor_window > 0 and any(
        c.missing is not None and c.missing.level == "sensor_reading" for c in chains.factors
    )
    back = _look_back(
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


# --- looking back ----------------------------------------------------------------------------


@dataclass(slots=True)
class _Back:
    window: list[Cycle]
    prev_sealed: Cycle | None
    held: HeldSince


def _look_back(
    log: Log,
    target: Cycle,
    command: str | None,
    lookback_ns: int,
    window_cycles: int,
    *,
    period_ns: int,
) -> _Back:
    """One reverse walk: previous seal, where the current command began, sensor window.

    The walk reads at most ``lookback_ns`` of log (or the sensor window, if longer) and
    stops as soon as it has what it needs; ``window_cycles=0`` skips the window. Only a gap
    longer than that before the decision sends it further back, for the previous seal.
    """
    window: list[Cycle] = []
    prev_sealed: Cycle | None = None
    since, count = target, 1
    bound: Literal["change", "lookback", "log_start"] = "log_start"
    previous: Cycle | None = None
    holding = True
    floor = target.t_ns - lookback_ns
    start = max(0, min(floor, target.t_ns - 2 * (window_cycles + 1) * period_ns))
    for earlier in _reverse_from(log, target.t_ns, start):
        if earlier.cycle >= target.cycle:
            continue
        if len(window) < window_cycles:
            window.append(earlier)
        if prev_sealed is None and TOPIC_SEAL in earlier.payloads:
            prev_sealed = earlier
        if holding:
            if earlier.t_ns < floor:
                holding, bound = False, "lookback"
            elif command_of(earlier) == command:
                since, count = earlier, count + 1
            else:
                holding, bound, previous = False, "change", earlier
        if not holding and prev_sealed is not None and len(window) >= window_cycles:
            break
    else:
        if holding and start > log.start_ns:
            bound = "lookback"  # the walk's bound, not the log's start, stopped it
        if prev_sealed is None and start > log.start_ns:
            prev_sealed = next(
                (c for c in log.iter_cycles(end_ns=start - 1, reverse=True) if c.sealed),
                None,
            )
    held = HeldSince(
        command=command,
        since_cycle=since.cycle,
        since_t_ns=since.t_ns,
        cycles=count,
        bound=bound,
        previous=command_of(previous) if previous is not None else None,
        previous_cycle=previous.cycle if previous is not None else None,
        at_least=bound != "change",
    )
    return _Back(window, prev_sealed, held)


def _reverse_from(log: Log, t_ns: int, start_ns: int) -> Iterator[Cycle]:
    """Cycles from ``t_ns`` back to ``start_ns``, newest first, in widening windows.

    The reader lists the chunks of a window before decoding any, so a walk that usually
    stops within a second should not ask for ten minutes at once: windows of 1 s, 10 s,
    100 s, ... up to ``start_ns``.
    """
    hi, span = t_ns, 1_000_000_000
    while hi >= start_ns:
        lo = max(start_ns, t_ns - span)
        yield from log.iter_cycles(start_ns=lo, end_ns=hi, reverse=True)
        hi, span = lo - 1, span * 10


def _check_seal(log: Log, target: Cycle, prev_sealed: Cycle | None) -> SealCheck:
    if prev_sealed is not None:
        expected = digest(prev_sealed.payloads[TOPIC_SEAL])
        prev_cycle: int | None = prev_sealed.cycle
        source = f"the previous seal (cycle {prev_sealed.cycle})"
    else:
        segment = log.segment_named(target.segment)
        expected = segment.session.prev_seal if segment is not None else GENESIS
        prev_cycle = None
        source = (
            "genesis (first seal of the robot)"
            if expected == GENESIS
            else "the segment's recorded prev_seal (previous segment not in this log)"
        )
    status = verify_cycle(target, expected)
    sealed = status.state != "unsealed"
    in_flight = not sealed and _in_flight(log, target)
    content_bad = bool(status.modified or status.missing or status.extra)
    compared = sealed and (content_bad or len(target.payloads) > 1)
    prev_ok = {"ok": True, "broken": False}.get(status.link) if sealed else None
    problems: list[str] = []
    if in_flight:
        problems.append(
            "the robot stopped while writing this cycle: it was never sealed, so its content "
            "cannot be verified"
        )
    elif not sealed:
        problems.append("the cycle is not sealed")
    problems += [f"{t} does not match its seal digest" for t in status.modified]
    problems += [f"{t} is logged but not named by the seal" for t in status.extra]
    problems += [f"{t} is named by the seal but missing" for t in status.missing]
    problems += [f"evidenced reading {r} differs from its ref" for r in status.evidence_mismatch]
    if status.state == "modified" and not content_bad and status.detail:
        problems.append(status.detail)  # e.g. a malformed seal, or one naming another cycle
    if prev_ok is False:
        problems.append(f"prev does not match the digest of {source}")
    return SealCheck(
        state=status.state,
        sealed=sealed,
        digests_ok=(not content_bad) if compared else None,
        mismatched=status.modified,
        unnamed=status.extra,
        absent=status.missing,
        summarised=status.summarised,
        evidence_checked=status.evidence_checked,
        evidence_mismatch=status.evidence_mismatch,
        prev_ok=prev_ok,
        prev_cycle=prev_cycle,
        prev_source=source,
        dropped_before=status.dropped,
        verified=sealed and not problems,
        problems=tuple(problems),
        in_flight=in_flight,
    )


def _in_flight(log: Log, target: Cycle) -> bool:
    """Whether an unsealed cycle is the one the robot was writing when it stopped.

    verify's rule (``trace_runtime.verification``, the unsealed check): unsealed cycles after
    the last seal of a segment the robot never closed are the crash's cut, anything else
    without a seal is a finding. The segment's newest cycles are read back to its last seal.
    """
    segment = log.segment_named(target.segment)
    if segment is None or segment.finished:
        return False
    for cycle in segment.iter_cycles(reverse=True):
        if cycle.sealed:
            return False
        if cycle.cycle == target.cycle and cycle.t_ns == target.t_ns:
            return True
    return False


def _scores(
    target: Cycle,
    chains: DecisionChains,
    seal: SealCheck,
    *,
    prev_sealed: Cycle | None,
    period_ns: int,
    config: MetricsConfig | None = None,
) -> DecisionScores:
    """This decision's ET, ET_partial, DR and TCS, by the same definitions as the metrics."""
    config = config or MetricsConfig()
    problems: list[str] = []
    if chains.reason:
        problems.append(f"ET: {chains.reason}")
    for factor in chains.factors:
        link = factor.missing
        if link is not None:
            problems.append(
                f"ET: {factor.name or factor.node}: {link.level} not documented "
                f"({link.detail}); depth {factor.depth}/{factor.expected_depth}"
            )
    missing_dr = dr_problems(target.layer(TOPIC_ACTION))
    problems += [f"DR: {p}" for p in missing_dr]
    problems += [f"integrity: {p}" for p in seal.problems]
    continuity_d = 1.0
    if prev_sealed is not None and target.t_ns > prev_sealed.t_ns:
        continuity_d = continuity(target.t_ns - prev_sealed.t_ns, period_ns, config.gap_tolerance)
    tcs = trust_score(
        config.weights,
        et=chains.et,
        et_partial=chains.et_partial,
        dr_ok=not missing_dr,
        continuity=continuity_d,
        intact=seal.verified,
    )
    return DecisionScores(
        et=chains.et,
        et_partial=chains.et_partial,
        fully_traceable=chains.fully_traceable,
        dr=0.0 if missing_dr else 1.0,
        tcs=tcs,
        problems=tuple(problems),
        source="trace_audit.metrics definitions (docs/metrics.md), default TCS weights",
    )
