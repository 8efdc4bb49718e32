"""What ``explain`` answers about one decision, as typed results: ``Explanation`` and its
parts (whether the seal holds, since when the command held, the decision's scores)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from trace_audit.causal import Decision, GraphData
from trace_audit.chains import DecisionChains
from trace_audit.evidence import ExternalEvidence
from trace_audit.jsonout import OMIT_EMPTY
from trace_audit.log_time import LogClock
from trace_audit.sensor_health import SensorHealth
from trace_runtime.gaps import gap_limit_ns

__all__ = ["DecisionScores", "Explanation", "HeldSince", "SealCheck"]


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
    why a score is below 1. ET, ET_partial and TCS are None when unknown: a factor's chain
    stops at a reading in a recording that could not be read (never 0 for that).
    """

    et: float | None
    et_partial: float | None
    fully_traceable: bool
    dr: float
    tcs: float | None
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
    graph: GraphData
    tree: GraphData | None
    external_evidence: tuple[ExternalEvidence, ...] = ()
    """The decision's evidence refs into external recordings: resolved (and decoded),
    broken, or unresolved (recording not given)."""
    clock_run: tuple[str, ...] = ()
    """When the robot's clock restarted in the log: the segments of the run that holds the
    decision (a time may name a decision in another run too); empty otherwise."""
    live: bool | None = field(default=None, metadata={OMIT_EMPTY: True})
    """True when a segment of the log is being written right now (its logger holds the
    lock); None otherwise, and then left out of the JSON."""
    channel_evidence: tuple[ExternalEvidence, ...] = field(default=(), metadata={OMIT_EMPTY: True})
    """The messages the execution's actuator channels cite as where ``actual`` was read
    from (profile 1.4), resolved and decoded as external evidence is; left out of the JSON
    when no channel cites one."""
    sensors: SensorHealth | None = None
    """The sensors the decision used and missed, and the age of each reading it cited."""

    @property
    def log_clock(self) -> LogClock:
        """How this log's times are shown (``log_time.LogClock``)."""
        return LogClock(self.clock, self.log_start_ns)

    @property
    def stale(self) -> bool:
        """True when the time from the decision to the query would be a gap (the one gap
        rule, ``trace_runtime.gaps``): no decision was logged when one was due."""
        return self.period_ns > 0 and self.offset_ns > gap_limit_ns(self.period_ns)
