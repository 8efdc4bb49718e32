"""``verify``: is this log what the robot wrote, all of it, in order?

The investigator's thin front on ``trace_runtime.verification`` (which owns every rule of
the verdict): ``verify_log`` takes what an investigator has at hand (a path, external
recordings to resolve evidence refs in), opens the log through the one owner of multi-file
logs (``trace_runtime.reading.logset.open_log``: which copy of a segment is read, which files could
not be read) and the recordings (``trace_audit.evidence``), and hands both to
``trace_runtime.verification.verify``. Retention in the runtime deletes only what that
same verification finds clean. For one decision (``explain``) the check is
``trace_runtime.encoding.seal_check.verify_cycle``. See docs/integrity.md.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from trace_audit.evidence import recordings_for
from trace_audit.selection import Selection
from trace_runtime.errors import NoteError, UsageError
from trace_runtime.gaps import JSON_INLINE
from trace_runtime.reading.logset import open_log
from trace_runtime.tlog.keys import PublicKey
from trace_runtime.tlog.signed_note import NoteVerifier, parse_verifier_key
from trace_runtime.verification import (
    Finding,
    FindingKind,
    NoteKind,
    RobotSummary,
    SegmentSummary,
    VerifyReport,
    verify,
)

if TYPE_CHECKING:
    from trace_audit.witness.compare import WitnessReport

__all__ = [
    "Finding",
    "FindingKind",
    "NoteKind",
    "RobotSummary",
    "SegmentSummary",
    "VerifyReport",
    "WitnessedVerifyReport",
    "add_witness",
    "verify_log",
    "verify_witnessed",
    "witness_check",
]


def verify_log(
    path: str | Path,
    *,
    key: PublicKey | None = None,
    evidence: Sequence[str | Path] = (),
    executor: Executor | None = None,
    robots: Sequence[str] = (),
) -> VerifyReport:
    """Verify a segment file, a directory of segments or a log root; never raises on tampering.

    ``evidence``: external recordings (MCAP files, rosbag2 directories) that evidence refs
    name: each such ref is resolved and its digest checked there (a mismatch is a finding);
    refs into recordings not given are counted as unresolved (a note), not as broken.
    Raises ``LogReadError`` only when nothing readable is there (exit 3 at the CLI); a damaged
    segment inside a root is a finding. ``robots``: only these robots' chains
    (``selection.Selection``).
    """
    log = Selection(tuple(robots)).of(open_log(path))
    return verify(log, key=key, recordings=recordings_for(log, evidence), executor=executor)


def witness_check(
    path: str | Path,
    source: str,
    *,
    key: PublicKey | None = None,
    witness_key: NoteVerifier | None = None,
    robots: Sequence[str] = (),
    expected: Sequence[str] = (),
    announced: Mapping[str, Sequence[PublicKey]] | None = None,
) -> WitnessReport:
    """``verify --witness``: the log's robots compared with what a witness cosigned
    (``trace_audit.witness.compare``): ``source`` is a witness URL, a file of cosigned
    checkpoint notes, or ``local`` (the root's own ``witness/`` store). Its findings
    (``truncated_tail``, ``fork``, ``bad_signature``) belong in the verify report
    (``add_witness``). ``expected``: robots (or origins) the witness is asked about even
    when the log holds none of their segments (one deleted whole is a ``truncated_tail``).
    ``announced``: each robot's keys rotated to from ``key`` (``announced_keys``)."""
    from trace_audit.witness.compare import compare_witnessed

    log = Selection(tuple(robots)).of(open_log(path))
    return compare_witnessed(
        log, source, key=key, witness_key=witness_key, expected=expected, announced=announced
    )


def add_witness(report: VerifyReport, witness: WitnessReport) -> VerifyReport:
    """The verify report with the witness comparison's findings added (not ok when any)."""
    report.findings.extend(witness.findings)
    if witness.findings:
        report.ok = False
    return report


@dataclass(slots=True)
class WitnessedVerifyReport:
    """``verify --witness``: the verify report, the witness comparison's findings added to it
    (``add_witness``), and the comparison itself (its time bounds, what it read). As JSON:
    the report's fields, then ``witness``."""

    report: VerifyReport = field(metadata={JSON_INLINE: True})
    witness: WitnessReport

    @property
    def ok(self) -> bool:
        return self.report.ok


def verify_witnessed(
    path: str | Path,
    source: str,
    *,
    key: PublicKey | None = None,
    witness_key: str | None = None,
    evidence: Sequence[str | Path] = (),
    executor: Executor | None = None,
    robots: Sequence[str] = (),
    expected: Sequence[str] = (),
) -> WitnessedVerifyReport:
    """``verify_log`` and ``witness_check`` of one log, as one report. ``witness_key``: the
    witness's verifier key as text (``UsageError`` when it is not one)."""
    try:
        verifier = parse_verifier_key(witness_key) if witness_key else None
    except NoteError as err:
        raise UsageError(f"--witness-key: {err}") from err
    report = verify_log(path, key=key, evidence=evidence, executor=executor, robots=robots)
    # The robots' notes after a key rotation are signed by the keys their chains announced.
    announced = {
        r.robot_id: [parse_verifier_key(v).public_key for v in r.announced_keys]
        for r in report.robots
    }
    witnessed = witness_check(
        path,
        source,
        key=key,
        witness_key=verifier,
        robots=robots,
        expected=expected,
        announced=announced,
    )
    return WitnessedVerifyReport(add_witness(report, witnessed), witnessed)
