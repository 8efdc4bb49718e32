"""Whether a decision's seal holds: its digests (``trace_runtime.encoding.seal_check``), its
link to the previous seal, and whether an unsealed cycle is the one a crash cut short."""

from __future__ import annotations

from trace_audit.explanation.result import SealCheck
from trace_runtime.chain import GENESIS, digest
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.encoding.seal_check import verify_cycle
from trace_runtime.reading.logset import Log
from trace_runtime.records import TOPIC_SEAL

__all__ = ["check_seal"]


def check_seal(log: Log, target: Cycle, prev_sealed: Cycle | None) -> SealCheck:
    """Whether the decision's cycle matches its seal and its seal links to ``prev_sealed``
    (None: the segment's recorded ``prev_seal``, or genesis)."""
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
