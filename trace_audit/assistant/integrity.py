"""The integrity an answer carries, from ``trace-audit verify``'s report of the log it rests
on, and the verify reports this server already has.

An answer is about some robots of one log; its status is that of their chains, read whole
(every segment, every seal, the checkpoints): a broken link anywhere in a chain makes what
follows it unproven, so a finding outside the cycles an answer cites still fails it. A
whole verify of a large log takes a while (a 24 h log of one robot: seconds), so each
report is kept for the server's life, keyed by the log's files, sizes and modification
times (``roots.fingerprint``): the first question on a log pays for it, later ones do not,
and a log that changes (a live segment growing, a byte edited) is verified again.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from trace_audit.assistant.answers import Integrity, IntegrityFinding, IntegrityScope
from trace_runtime.errors import NoteError, UsageError
from trace_runtime.tlog.keys import load_public_key
from trace_runtime.tlog.signed_note import COSIGNATURE, parse_verifier_key

__all__ = ["FINDINGS_SHOWN", "VerifyCache", "VerifyKeys", "integrity_of", "unverified"]

FINDINGS_SHOWN = 5
"""Findings an answer lists (findings_total counts the rest)."""
_CACHED_LOGS = 32
"""Verify reports kept (the least recently used goes first)."""


@dataclass(frozen=True, slots=True)
class VerifyKeys:
    """The keys the server checks signatures with (``mcp --key``, ``--witness-key``): the
    robot's public key file (checkpoint signatures, followed through the key rotations the
    chain announces, as ``verify --key``) and the witness's verifier key (the cosignatures
    of the log root's own witness store, as ``verify --witness local --witness-key``)."""

    key: str | None = None
    witness_key: str | None = None

    @classmethod
    def checked(cls, key: Path | None, witness_key: str | None) -> VerifyKeys:
        """The keys, each read now so a bad one stops the server before it serves."""
        if key is not None:
            load_public_key(key)
        if witness_key is not None:
            try:
                verifier = parse_verifier_key(witness_key)
            except NoteError as err:
                raise UsageError(f"--witness-key: {err}") from err
            if verifier.sig_type != COSIGNATURE:
                raise UsageError(
                    "--witness-key: not a cosignature key (witness vkey --cosignature)"
                )
        return cls(str(key.resolve()) if key is not None else None, witness_key)

    def args(self) -> dict[str, str]:
        """The verify question's arguments for them."""
        given = {"key": self.key, "witness_key": self.witness_key}
        return {name: value for name, value in given.items() if value is not None}

    def options(self) -> dict[str, str | None]:
        """The ``trace-audit verify`` options that check the same."""
        witness = "local" if self.witness_key is not None else None
        return {"key": self.key, "witness": witness, "witness_key": self.witness_key}


def _concerns(robot_id: str, robots: Sequence[str]) -> bool:
    return not robots or robot_id in ("", *robots)


def integrity_of(report: dict[str, Any], robots: Sequence[str], *, cached: bool) -> Integrity:
    """The integrity of an answer about ``robots`` (none: every robot) of the log whose
    verify JSON (``to_jsonable(VerifyReport)``) is ``report``."""
    findings = [f for f in report.get("findings", []) if _concerns(f.get("robot_id", ""), robots)]
    chains = [r for r in report.get("robots", []) if _concerns(r.get("robot_id", ""), robots)]
    segments = [s for s in report.get("segments", []) if _concerns(s.get("robot_id", ""), robots)]
    witness = report.get("witness")
    bounds = [
        b for b in (witness or {}).get("bounds", []) if _concerns(b.get("robot_id", ""), robots)
    ]
    scope = IntegrityScope(
        source=str(report.get("path", "")),
        robots=[str(r["robot_id"]) for r in chains],
        segments=len(segments),
        cycles=sum(int(r.get("cycles", 0)) for r in chains),
        cycles_valid=sum(int(r.get("cycles_valid", 0)) for r in chains),
        signatures_checked=bool(report.get("signatures_checked", False)),
        witness_checked=witness is not None,
        witnessed=sum(1 for b in bounds if b.get("cosignature_checked")),
        cached=cached,
    )
    shown = [_finding(f) for f in findings[:FINDINGS_SHOWN]]
    if findings:
        first = shown[0]
        where = (
            f" cycles {first.first_cycle}..{first.last_cycle}"
            if first.first_cycle is not None
            else ""
        )
        robot = f" of {first.robot}" if first.robot else ""
        summary = (
            f"integrity failed: {len(findings)} finding(s) in the log this answer rests on; "
            f"first: {first.kind}{robot}{where}: {first.message}"
        )
        status = "integrity_failed"
    else:
        summary = (
            f"verified: {scope.cycles} cycles of {', '.join(scope.robots) or 'no robot'} in "
            f"{scope.segments} segment(s) match their seals and chain" + _signatures(scope, bounds)
        )
        status = "verified"
    return Integrity(
        status=status,
        summary=summary,
        findings=shown,
        findings_total=len(findings),
        scope=scope,
    )


def _signatures(scope: IntegrityScope, bounds: list[dict[str, Any]]) -> str:
    """What the verified status says of signatures: checked with the server's key (and the
    witness's), or not checked."""
    if not scope.signatures_checked:
        said = "; checkpoint signatures not checked (the server was given no --key)"
    else:
        said = "; their checkpoints are signed by the robot's key (or keys its chain announced)"
    if not scope.witness_checked:
        return said + " (trace-audit verify)"
    if not bounds:
        return said + "; no checkpoint of theirs is cosigned in the root's witness store"
    newest = max(bounds, key=lambda b: int(b.get("timestamp", 0)))
    return (
        f"{said}; {scope.witnessed} checkpoint(s) cosigned by the witness agree with the log, "
        f"the newest logged no later than {newest.get('time', '')} (trace-audit verify)"
    )


def _finding(f: dict[str, Any]) -> IntegrityFinding:
    return IntegrityFinding(
        kind=str(f.get("kind", "")),
        robot=str(f.get("robot_id", "")),
        segment=str(f.get("segment", "")),
        first_cycle=f.get("first_cycle"),
        last_cycle=f.get("last_cycle"),
        message=str(f.get("message", "")),
    )


def unverified(why: str) -> Integrity:
    """The integrity of an answer nothing was verified for, saying ``why``."""
    return Integrity(
        status="unverified",
        summary=f"unverified: {why}",
        findings=[],
        findings_total=0,
        scope=None,
    )


class VerifyCache:
    """Verify reports (JSON) by log path and fingerprint, the most recent ``_CACHED_LOGS``."""

    def __init__(self) -> None:
        self._reports: OrderedDict[tuple[str, object], dict[str, Any]] = OrderedDict()

    def get(self, path: str, fingerprint: object) -> dict[str, Any] | None:
        key = (path, fingerprint)
        report = self._reports.get(key)
        if report is not None:
            self._reports.move_to_end(key)
        return report

    def put(self, path: str, fingerprint: object, report: dict[str, Any]) -> None:
        if fingerprint is None:  # too many files to tell a change: never reused
            return
        for key in [k for k in self._reports if k[0] == path]:
            del self._reports[key]  # an older state of the same log
        self._reports[(path, fingerprint)] = report
        while len(self._reports) > _CACHED_LOGS:
            self._reports.popitem(last=False)
