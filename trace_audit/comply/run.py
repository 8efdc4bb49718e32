"""``comply``: a log root checked against a compliance profile, clause by clause, and the
adoption of a profile by a root (so that compaction and retention keep what it asks).

A clause is met when every check it names is met; the root conforms to the profile when
every clause is met. The root is read once (``evidence.gather``); each clause judges its
checks on that evidence (``retention`` with the clause's own period).
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass
from pathlib import Path

from trace_audit.comply.checks import CheckResult, Verdict, run_check
from trace_audit.comply.evidence import RootEvidence, gather
from trace_audit.comply.profile import CHECK_NAMES, Clause, Profile
from trace_runtime.errors import UsageError
from trace_runtime.tiers.keep import KeptProfile, RootKeep, adopt_profile
from trace_runtime.tlog.keys import PublicKey

__all__ = ["ClauseResult", "ComplianceReport", "adopt", "comply", "report_json"]


@dataclass(frozen=True, slots=True)
class ClauseResult:
    """One clause of the profile: where it is in the law, what it asks, and its checks."""

    reference: str
    summary: str
    verdict: Verdict
    checks: tuple[CheckResult, ...]
    keep_days: int | None = None

    @property
    def met(self) -> bool:
        return self.verdict == "met"


@dataclass(frozen=True, slots=True)
class ComplianceReport:
    """The result of ``comply``: every clause with its verdict, and how to reproduce it."""

    root: str
    profile: str
    title: str
    profile_path: str
    applies_from: str | None
    source: str | None
    clauses: tuple[ClauseResult, ...]
    command: str
    """The command that reproduces this report (keys by the paths given)."""
    verify_command: str
    check_commands: dict[str, str]
    """Per check, the command that shows its evidence on its own."""

    @property
    def conforms(self) -> bool:
        return all(c.met for c in self.clauses)

    @property
    def failed(self) -> list[ClauseResult]:
        return [c for c in self.clauses if not c.met]


def comply(
    root: str | Path,
    profile: Profile,
    *,
    key: PublicKey | None = None,
    witness_key: str | None = None,
    key_path: str | None = None,
    profile_arg: str | None = None,
) -> ComplianceReport:
    """Check ``root`` against every clause of ``profile``. ``witness_key``: the witness's
    verifier key as text; ``key_path``/``profile_arg``: how the user named the key and the
    profile, for the command that reproduces the report."""
    root = Path(root)
    if not root.is_dir():
        raise UsageError(f"{root}: comply checks a log root (a folder with hot/ warm/ cold/)")
    asked = {check for clause in profile.clauses for check in clause.checks}
    evidence = gather(
        root,
        key=key,
        witness_key=witness_key,
        witnessed="witnessed" in asked,
        safety="safety_rules" in asked,
        profile=profile_arg or profile.name,
    )
    clauses = tuple(_judge(evidence, clause) for clause in profile.clauses)
    command, verify, per_check = _commands(root, profile_arg or profile.path, key_path, witness_key)
    return ComplianceReport(
        root=str(root),
        profile=profile.name,
        title=profile.title,
        profile_path=profile.path,
        applies_from=profile.applies_from,
        source=profile.source,
        clauses=clauses,
        command=command,
        verify_command=verify,
        check_commands=per_check,
    )


def _judge(evidence: RootEvidence, clause: Clause) -> ClauseResult:
    results = tuple(run_check(name, evidence, clause) for name in clause.checks)
    verdict: Verdict = "met" if all(r.verdict == "met" for r in results) else "not met"
    return ClauseResult(clause.reference, clause.summary, verdict, results, clause.keep_days)


def _commands(
    root: Path, profile: str, key_path: str | None, witness_key: str | None
) -> tuple[str, str, dict[str, str]]:
    """(the comply command, the verify command, per check the command showing its evidence)."""
    key = f" --key {shlex.quote(key_path)}" if key_path else ""
    witness = f" --witness-key {shlex.quote(witness_key)}" if witness_key else ""
    where = shlex.quote(str(root))
    command = f"trace-audit comply {where} --profile {shlex.quote(profile)}{key}{witness}"
    verify = f"trace-audit verify {where}{key}"
    per_check: dict[str, str] = {name: f"{command} --json" for name in CHECK_NAMES}
    per_check |= {"chain": verify, "gaps": verify, "signed": verify}
    per_check["witnessed"] = f"{verify} --witness local{witness}"
    return command, verify, per_check


def adopt(root: str | Path, profile: Profile) -> RootKeep:
    """Write ``profile``'s period into ``root`` (``compliance.toml``): compaction and retention
    then keep every record younger than it. ``UsageError`` for a profile with no period."""
    days = profile.keep_days
    if days is None:
        raise UsageError(f"profile {profile.name} keeps no period (no clause with keep_days)")
    return adopt_profile(Path(root), KeptProfile(profile.name, days, profile.full_detail))


def report_json(report: ComplianceReport) -> dict[str, object]:
    """``comply --json``: the verdict, then every clause with its verdict and its checks."""
    return {
        "root": report.root,
        "profile": report.profile,
        "title": report.title,
        "profile_path": report.profile_path,
        "applies_from": report.applies_from,
        "conforms": report.conforms,
        "clauses": [
            {
                "reference": c.reference,
                "summary": c.summary,
                "verdict": c.verdict,
                "keep_days": c.keep_days,
                "checks": [
                    {
                        "check": r.check,
                        "verdict": r.verdict,
                        "what": r.what,
                        "evidence": list(r.evidence),
                        "fix": r.fix,
                    }
                    for r in c.checks
                ],
            }
            for c in report.clauses
        ],
        "command": report.command,
    }
