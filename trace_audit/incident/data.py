"""What the incident report shows, gathered from the investigator's own library calls.

``gather_report`` asks the same questions the terminal commands ask, and nothing else:
``explain`` for the decision at t, ``timeline`` for the commands over the window,
``compute_metrics`` (with the window as its analysis window) for TC, gaps and drops, and
``verify`` over the segments that hold the window for integrity. What the figures need
beyond that (a factor's value in each cycle of the window, the scene at t) is read from the
same cycles with ``read_decision`` and the chain walker's ``SensorWindow``, so a number in
the report is the number ``explain --json`` prints.

The window runs from two thirds of ``window_s`` before t to one third after it (clipped to
the log): how the situation built up, and what the robot did next.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from trace_audit.causal import (
    Decision,
)
from trace_audit.evidence import recordings_for
from trace_audit.explanation import Explanation, explain
from trace_audit.incident.window import (
    EntityView,
    RobotPose,
    Sample,
    entities_at,
    robot_pose,
    window_samples,
)
from trace_audit.log_source import as_log
from trace_audit.log_time import LogClock, TimeArg
from trace_audit.metrics import MetricsConfig, MetricsReport, compute_metrics
from trace_audit.rules import RobotRules, Rule, check_rules
from trace_audit.transitions import Timeline, timeline
from trace_runtime.errors import UsageError
from trace_runtime.reading.logset import Log
from trace_runtime.reading.reader import RECOVERED_WARNING, Segment
from trace_runtime.reading.recordings import Recordings
from trace_runtime.records import TOPIC_PERCEPTION
from trace_runtime.session import SessionInfo
from trace_runtime.tlog.keys import PublicKey
from trace_runtime.verification import VerifyReport, verify

__all__ = ["DEFAULT_WINDOW_S", "ReportData", "Verdict", "gather_report", "parse_window"]

DEFAULT_WINDOW_S = 30.0
MAX_WINDOW_S = 3600.0
"""A report is about one incident; an hour of cycles is already ~36,000 points per line."""


def parse_window(text: str) -> float:
    """``30``, ``30s``, ``2m`` or ``1.5min`` as seconds; ``UsageError`` on anything else."""
    raw = text.strip().lower()
    scale = 1.0
    for suffix, factor in (("min", 60.0), ("m", 60.0), ("s", 1.0)):
        if raw.endswith(suffix):
            raw, scale = raw[: -len(suffix)], factor
            break
    try:
        seconds = float(raw) * scale
    except ValueError:
        seconds = float("nan")
    if not 0 < seconds <= MAX_WINDOW_S:
        raise UsageError(
            f"invalid window {text!r}: give seconds (30, 30s) or minutes (2m), "
            f"more than 0 and at most {MAX_WINDOW_S:.0f} s"
        )
    return seconds


@dataclass(frozen=True, slots=True)
class Verdict:
    """The report's integrity verdict: what the page's badges, the terminal line and --json
    all say, so that no two of them disagree.

    ``kind``: ``failed`` (a finding in the segments holding the window, or this decision's
    seal does not verify), ``unsealed`` (the decision is the cycle the robot was writing when
    it was killed: nothing failed, but its content cannot be verified), ``not_anchored``
    (clean, but no checkpoint there vouches for this decision yet) or ``clean``.
    """

    kind: Literal["clean", "not_anchored", "unsealed", "failed"]
    findings: int
    decision_verified: bool
    anchored: bool
    anchored_through: int | None
    """The last cycle a checkpoint in the segments holding the window vouches for."""
    unanchored: tuple[int, int] | None
    """The cycles there no checkpoint vouches for yet (first, last), if any."""

    @property
    def ok(self) -> bool:
        """Nothing failed (an unsealed cycle in flight or a missing anchor is no failure)."""
        return self.kind != "failed"


@dataclass(frozen=True, slots=True)
class ReportData:
    """Everything the incident report shows, each part from its library owner."""

    path: str
    explanation: Explanation
    session: SessionInfo
    window_s: float
    start_ns: int
    end_ns: int
    timeline: Timeline
    samples: tuple[Sample, ...]
    factor_units: dict[str, str | None]
    entities: tuple[EntityView, ...]
    entities_retained: bool
    robot: RobotPose | None
    metrics: MetricsReport
    integrity: VerifyReport
    integrity_scope: tuple[str, ...]
    key_id: str | None
    not_retained: tuple[str, ...] = field(default=())
    evidence: tuple[str, ...] = ()
    """The external recordings given (``--evidence``), as the investigator named them."""
    window_inputs: tuple[str, ...] = ()
    """What the window's metrics read when not the whole log: the segment files of the
    decision's robot (the log holds others) and of the run of its clock that holds the
    decision (its clock restarted in the log)."""
    key_path: str | None = None
    """The public key file given (``--key``), as the investigator named it."""
    robot_option: str | None = None
    """The decision's robot when the log holds others: the page's commands name it."""
    rules: RobotRules | None = None
    """The safety rules given (``--rules``) judged over the window, on the decision's robot."""
    rules_path: str | None = None
    """The rules file given, as the investigator named it."""

    @property
    def decision(self) -> Decision:
        return self.explanation.decision

    @property
    def verdict(self) -> Verdict:
        """The one integrity verdict of the report (see ``Verdict``)."""
        e, report = self.explanation, self.integrity
        robot = next((r for r in report.robots if r.robot_id == e.robot), None)
        through = robot.anchored_cycle if robot is not None else None
        # An unsealed cycle is not in the chain, so no checkpoint can vouch for it.
        anchored = e.seal.sealed and through is not None and e.cycle <= through
        unanchored = None
        last = robot.cycle_range.last_cycle if robot is not None else None
        if robot is not None and last is not None:
            first = through + 1 if through is not None else robot.cycle_range.first_cycle
            if first is not None and first <= last:
                unanchored = (first, last)
        kind: Literal["clean", "not_anchored", "unsealed", "failed"]
        if not report.ok or not (e.seal.verified or e.seal.in_flight):
            kind = "failed"
        elif e.seal.in_flight:
            kind = "unsealed"
        else:
            kind = "clean" if anchored else "not_anchored"
        return Verdict(
            kind=kind,
            findings=len(report.findings),
            decision_verified=e.seal.verified,
            anchored=anchored,
            anchored_through=through,
            unanchored=unanchored,
        )


def gather_report(
    path: str | Path,
    *,
    t: TimeArg = None,
    cycle: int | None = None,
    window_s: float = DEFAULT_WINDOW_S,
    key: PublicKey | None = None,
    evidence: Sequence[str | Path] = (),
    robots: Sequence[str] = (),
    key_path: str | Path | None = None,
    rules: Sequence[Rule] = (),
    rules_path: str | Path | None = None,
) -> ReportData:
    """Gather the report of the decision in force at ``t`` (or cycle ``cycle``) in a log.

    ``evidence``: external recordings (MCAP files, rosbag2 directories) the log's evidence
    refs may name; explain, metrics and verify resolve and digest-check them there.
    ``robots`` as ``explain`` takes them: the report is of one robot's decision, and its
    window, metrics and integrity are that robot's. ``key_path``: where ``key`` was read
    from, for the page's Reproduce commands. ``rules`` (read from ``rules_path``): safety
    rules judged over the window (``check``), shown in their own section."""
    if not 0 < window_s <= MAX_WINDOW_S:
        raise UsageError(f"window must be in (0, {MAX_WINDOW_S:.0f}] s, got {window_s}")
    given = as_log(path)
    # The one resolution of evidence of the page: the scene, the entity table, the evidence
    # section, the chains and figures, the metrics and the integrity verdict all read it.
    recordings = recordings_for(given, evidence)
    result = explain(given, t=t, cycle=cycle, robots=robots, recordings=recordings)
    whole = given.of_robots([result.robot])
    log = whole.clock_run(result.decision.segment)
    start, end = _window(log, result.t_ns, window_s)
    spans = timeline(log, start=start, end=end)
    samples, target, sensors = window_samples(log, start, end, result, recordings)
    inputs = () if log is given else tuple(str(s.path) for s in log.segments)
    scope = [s for s in log.segments if s.end_ns >= start and s.start_ns <= end]
    return ReportData(
        path=str(path),
        explanation=result,
        session=_session_of(log, result.decision.segment),
        window_s=window_s,
        start_ns=start,
        end_ns=end,
        timeline=spans,
        samples=samples,
        factor_units={f.label: f.unit for f in result.decision.factors},
        entities=entities_at(target, sensors, LogClock.of(log)) if target is not None else (),
        entities_retained=target is not None and TOPIC_PERCEPTION in target.payloads,
        robot=robot_pose(target) if target is not None else None,
        metrics=_window_metrics(whole, list(inputs) or [path], start, end, recordings),
        integrity=_window_integrity(whole, scope, log.root, key, recordings),
        integrity_scope=tuple(s.path.name for s in scope),
        key_id=key.key_id if key is not None else None,
        key_path=None if key_path is None else str(key_path),
        robot_option=result.robot if len(given.robots) > 1 else None,
        evidence=tuple(str(e) for e in evidence),
        not_retained=_not_retained(result),
        window_inputs=inputs,
        rules=check_rules(log, rules, start=start, end=end).robots[0] if rules else None,
        rules_path=None if rules_path is None else str(rules_path),
    )


def _window(log: Log, t_ns: int, window_s: float) -> tuple[int, int]:
    """The report's window around a decision at ``t_ns``: two thirds of ``window_s``
    before it, one third after, clipped to the log."""
    start = max(log.start_ns, t_ns - int(window_s * 2 / 3 * 1e9))
    return start, min(log.end_ns, start + int(window_s * 1e9))


def _session_of(log: Log, segment: str) -> SessionInfo:
    """The session of the segment holding the decision (the log's first if none does)."""
    return next(
        (s.session for s in log.segments if s.path.name == segment), log.segments[0].session
    )


def _window_metrics(
    whole: Log, inputs: list[str | Path], start: int, end: int, recordings: Recordings | None
) -> MetricsReport:
    """The window's auditability, by ``compute_metrics`` over its files (``inputs``)."""
    with _warned_once(whole):
        return compute_metrics(
            inputs, MetricsConfig(start_ns=start, end_ns=end), recordings=recordings
        )


def _window_integrity(
    whole: Log,
    scope: Sequence[Segment],
    root: Path,
    key: PublicKey | None,
    recordings: Recordings | None,
) -> VerifyReport:
    """verify of the window's segments, told what it could not see: a chain that starts
    after segment 0 there is the window's start when the log holds the earlier segments,
    not retention having removed them."""
    report = verify(Log(scope, root), key=key, recordings=recordings)
    first = min((s.session.segment for s in scope), default=0)
    earlier = any(s.session.segment < first for s in whole.segments)
    if not earlier:
        return report
    report.notes = [
        dataclasses.replace(
            n,
            message=f"verified from segment {first}, the first that holds the window; the "
            "earlier segments are in the log but outside the window (trace-audit verify on "
            "the whole log checks the chain into it)",
        )
        if n.kind == "chain_start"
        else n
        for n in report.notes
    ]
    return report


class _SaidAlready(logging.Filter):
    """Drops the reader's recovered-segment warning for a file it was already given for."""

    def __init__(self, paths: set[Path]) -> None:
        super().__init__()
        self.paths = paths

    def filter(self, record: logging.LogRecord) -> bool:
        args = record.args
        if (
            record.msg == RECOVERED_WARNING
            and isinstance(args, tuple)
            and args
            and isinstance(args[0], str | Path)
        ):
            return Path(args[0]).resolve() not in self.paths
        return True


@contextmanager
def _warned_once(log: Log) -> Iterator[None]:
    """While the metrics open the log's files a second time (they take paths, not an open
    ``Log``), keep the reader from repeating what it said when they were first opened: "no
    summary (unfinished segment); recovered N messages by scan" once per file is enough."""
    said = _SaidAlready({s.path.resolve() for s in log.segments if not s.finished})
    logger = logging.getLogger("trace_runtime")
    logger.addFilter(said)
    try:
        yield
    finally:
        logger.removeFilter(said)


def _not_retained(result: Explanation) -> tuple[str, ...]:
    """What a warm-tier summary cycle did not keep, in words (empty for a full cycle)."""
    d = result.decision
    if not d.summary:
        return ()
    out = ["the sensor readings (warm summaries keep the digests, not the data)"]
    out += [f"the full {topic} message" for topic in result.seal.summarised]
    return tuple(out)
