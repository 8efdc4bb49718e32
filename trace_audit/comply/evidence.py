"""What ``comply`` reads from a log root, once, before any clause is judged.

The verifier's report (``trace_audit.verify.verify_log``: one owner of what "verifies"
means), the witness comparison against the root's own store of cosigned checkpoints when a
clause asks for it (``witness_check(..., "local")``), each segment's session (which
software and policy versions wrote it), the safety-rule checks each decision records, the
root's adopted compliance profiles (``trace_runtime.tiers.keep``) and its retention journal.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import orjson

from trace_audit.verify import VerifyReport, verify_log, witness_check
from trace_runtime.boundary import read_side_file
from trace_runtime.errors import NoteError, UsageError
from trace_runtime.reading.logset import open_log
from trace_runtime.records import TOPIC_EXECUTION
from trace_runtime.tiers.keep import RootKeep, read_keep
from trace_runtime.tiers.retention import RETENTION_LOG
from trace_runtime.tlog.keys import PublicKey
from trace_runtime.tlog.signed_note import NoteVerifier, parse_verifier_key

if TYPE_CHECKING:
    from trace_audit.witness.compare import WitnessReport
    from trace_runtime.reading.logset import Log

__all__ = ["Deleted", "RootEvidence", "SafetyTally", "SegmentVersions", "gather"]


@dataclass(frozen=True, slots=True)
class SegmentVersions:
    """One segment of a robot: which software and policy wrote it, and when it ran."""

    robot: str
    segment: int
    name: str
    tier: str
    software: str
    policy: str
    start_ns: int
    end_ns: int
    cycles: int
    clock: str


@dataclass(slots=True)
class SafetyTally:
    """A robot's decisions and the safety-rule checks their execution records carry."""

    decisions: int = 0
    unchecked: int = 0
    first_unchecked: tuple[int, int] | None = None
    """(cycle, t_ns) of the first decision without a check."""
    clock: str = "system"
    rules: dict[str, int] = field(default_factory=dict)
    """Each rule checked, and how often it failed (a failed check is an intervention the
    log recorded, not a logging fault)."""


@dataclass(frozen=True, slots=True)
class Deleted:
    """A segment retention deleted (``retention.jsonl``)."""

    path: str
    robot: str
    end_ns: int


@dataclass(slots=True)
class RootEvidence:
    """Everything the checks read, gathered once."""

    root: Path
    report: VerifyReport
    versions: list[SegmentVersions]
    safety: dict[str, SafetyTally]
    keep: RootKeep | None
    deleted: list[Deleted]
    newest_ns: int
    key_given: bool
    profile: str
    """The profile's name as the user gave it (named in the fixes)."""
    witness: WitnessReport | None = None
    witness_key_given: bool = False


def gather(
    root: Path,
    *,
    key: PublicKey | None,
    witness_key: str | None,
    witnessed: bool,
    safety: bool,
    profile: str,
) -> RootEvidence:
    """Read ``root`` for the checks; ``witnessed``/``safety``: whether any clause asks for
    the witness comparison or the per-decision safety checks (each a read of its own)."""
    verifier = _verifier(witness_key)
    report = verify_log(root, key=key)
    log = open_log(root)
    evidence = RootEvidence(
        root=root,
        report=report,
        versions=_versions(log, report),
        safety=_safety(log) if safety else {},
        keep=read_keep(root),
        deleted=_deleted(root),
        newest_ns=log.end_ns,
        key_given=key is not None,
        profile=profile,
        witness_key_given=verifier is not None,
    )
    if witnessed:
        evidence.witness = witness_check(root, "local", key=key, witness_key=verifier)
    return evidence


def _verifier(text: str | None) -> NoteVerifier | None:
    if not text:
        return None
    try:
        return parse_verifier_key(text)
    except NoteError as err:
        raise UsageError(f"--witness-key: {err}") from err


def _versions(log: Log, report: VerifyReport) -> list[SegmentVersions]:
    """Each segment read, robot by robot in chain order, with the cycles verify counted."""
    cycles = {Path(s.path): s.cycles for s in report.segments}
    rows = [
        SegmentVersions(
            robot=s.session.robot_id,
            segment=s.session.segment,
            name=f"{s.path.parent.name}/{s.path.name}",
            tier=s.session.tier,
            software=s.session.software_version,
            policy=s.session.policy_version,
            start_ns=s.info.start_ns,
            end_ns=s.info.end_ns,
            cycles=cycles.get(Path(s.path), 0),
            clock=s.session.clock,
        )
        for s in log.segments
    ]
    return sorted(rows, key=lambda r: (r.robot, r.segment))


def _safety(log: Log) -> dict[str, SafetyTally]:
    """Per robot: its decisions and the safety-rule checks each execution record names."""
    tallies: dict[str, SafetyTally] = {}
    for robot in log.robots:
        clock = next(s.session.clock for s in log.segments if s.session.robot_id == robot)
        tally = tallies.setdefault(robot, SafetyTally(clock=clock))
        for cycle in log.iter_cycles(robot=robot):
            layer = cycle.layer(TOPIC_EXECUTION)
            checks = layer.get("checks") if isinstance(layer, dict) else None
            tally.decisions += 1
            named = [
                c for c in checks or () if isinstance(c, dict) and isinstance(c.get("rule"), str)
            ]
            if not named:
                tally.unchecked += 1
                if tally.first_unchecked is None:
                    tally.first_unchecked = (cycle.cycle, cycle.t_ns)
            for check in named:
                failed = check.get("passed") is False
                tally.rules[check["rule"]] = tally.rules.get(check["rule"], 0) + failed
    return tallies


def _deleted(root: Path) -> list[Deleted]:
    """The retention journal's deletions; lines not of its shape are skipped (a hint)."""
    data = read_side_file(root / RETENTION_LOG)
    out: list[Deleted] = []
    for line in (data or b"").splitlines():
        try:
            row = orjson.loads(line)
        except orjson.JSONDecodeError:
            continue
        if not isinstance(row, dict):
            continue
        path, robot, end = row.get("path"), row.get("robot"), row.get("end_ns")
        if isinstance(path, str) and isinstance(robot, str) and type(end) is int:
            out.append(Deleted(path, robot, end))
    return out
