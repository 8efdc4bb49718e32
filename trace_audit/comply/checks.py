"""The checks a profile's clauses name, each a function of the gathered ``RootEvidence``
(and of the clause, for the period it keeps): met or not, the evidence, and the fix.

Each check judges a technical logging condition only; none of them decides whether a law
applies to a machine or whether the machine conforms (docs/compliance.md).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

from trace_audit.comply.evidence import RootEvidence, SegmentVersions
from trace_audit.comply.profile import CheckName, Clause
from trace_runtime.clock import show_instant
from trace_runtime.tiers.compaction import DEFAULT_RETENTION_NS
from trace_runtime.tiers.durations import DAY_NS
from trace_runtime.tiers.keep import COMPLIANCE_NAME

__all__ = ["CHECKS", "WHAT", "CheckResult", "Verdict", "run_check"]

Verdict = Literal["met", "not met"]

WHAT: dict[CheckName, str] = {
    "versions": "every decision's segment names its software and policy versions; each "
    "change of version falls between two consecutive segments of the robot's chain",
    "signed": "every checkpoint carries a signature that verifies under the robot's key",
    "witnessed": "a witness cosigned each robot's checkpoints (the root's witness/ store)",
    "gaps": "no cycle is missing that the logger did not declare dropped",
    "chain": "trace-audit verify finds nothing: every cycle matches its seal, in one chain",
    "retention": "the root keeps every tier at least as long as the clause asks",
    "safety_rules": "every decision's execution record names the safety rules checked on it",
}
"""Each check in one line, for the JSON, the terminal and the evidence page."""


@dataclass(frozen=True, slots=True)
class CheckResult:
    """One check of one clause: its verdict, the evidence behind it, and the fix."""

    check: CheckName
    verdict: Verdict
    what: str
    evidence: tuple[str, ...]
    fix: str = ""


def run_check(name: CheckName, evidence: RootEvidence, clause: Clause) -> CheckResult:
    """Judge check ``name`` on ``evidence`` for ``clause``."""
    problems, found, fix = CHECKS[name](evidence, clause)
    verdict: Verdict = "not met" if problems else "met"
    return CheckResult(name, verdict, WHAT[name], (*problems, *found), fix if problems else "")


_Outcome = tuple[list[str], list[str], str]
"""(problems, other evidence, the fix): met when there is no problem."""


def _versions(ev: RootEvidence, _clause: Clause) -> _Outcome:
    problems: list[str] = []
    found: list[str] = []
    by_robot: dict[str, list[SegmentVersions]] = {}
    for row in ev.versions:
        by_robot.setdefault(row.robot, []).append(row)
    for robot, rows in sorted(by_robot.items()):
        deciding = [r for r in rows if r.cycles]
        for r in deciding:
            missing = [w for w, v in (("software", r.software), ("policy", r.policy)) if not v]
            if missing:
                problems.append(
                    f"{robot} {r.name}: {r.cycles} decisions name no {' and no '.join(missing)}"
                    " version"
                )
        first = deciding[0] if deciding else None
        if first is not None:
            found.append(
                f"{robot}: software {first.software or '?'!r}, policy "
                f"{first.policy or '?'!r} from {show_instant(first.start_ns, first.clock)}"
            )
        for before, after in itertools.pairwise(deciding):
            if (before.software, before.policy) == (after.software, after.policy):
                continue
            change = (
                f"{robot}: at {show_instant(after.start_ns, after.clock)} (segment "
                f"{after.segment}) software {before.software!r} -> {after.software!r}, "
                f"policy {before.policy!r} -> {after.policy!r}"
            )
            if after.segment != before.segment + 1:
                problems.append(
                    f"{change}: not visible, segments {before.segment + 1}.."
                    f"{after.segment - 1} between are not here"
                )
            else:
                found.append(change)
    fix = (
        "give the logger software_version and policy_version (AuditLogger(..., "
        "software_version=..., policy_version=...), or the recorder's hello) and keep "
        "every segment"
    )
    return problems, found or ["no decision in the root"], fix


def _signed(ev: RootEvidence, _clause: Clause) -> _Outcome:
    r = ev.report
    if not ev.key_given:
        return (
            ["signatures not checked: no robot public key given"],
            [],
            "pass --key ROBOT.pub (the key from trace-audit keygen)",
        )
    problems = [
        f"{f.robot_id} {f.segment}: {f.kind}: {f.message}"
        for f in r.findings
        if f.kind in ("bad_signature", "key_mismatch", "unsigned_checkpoint")
    ][:5]
    problems += [
        f"{s.robot_id}: no checkpoint vouches for any cycle"
        for s in r.robots
        if s.anchored_cycle is None
    ]
    if r.checkpoints_valid < r.checkpoints:
        problems.append(
            f"{r.checkpoints - r.checkpoints_valid} of {r.checkpoints} checkpoints do not verify"
        )
    found = [f"{r.checkpoints_valid} of {r.checkpoints} checkpoints verify under key {r.key_id}"]
    found += [
        f"{s.robot_id}: signed through cycle {s.anchored_cycle}"
        f" ({s.unanchored_cycles} later cycles not yet vouched for)"
        for s in r.robots
        if s.anchored_cycle is not None
    ]
    return (
        problems,
        found,
        ("sign checkpoints: LoggerConfig(checkpoint_key=...) or trace-sim run --key ROBOT.key"),
    )


def _witnessed(ev: RootEvidence, _clause: Clause) -> _Outcome:
    w = ev.witness
    fix = (
        "have the logger submit its checkpoints to a witness (LoggerConfig(witness=URL), "
        "trace-audit witness serve) and pass --witness-key VKEY"
    )
    if w is None:
        return ["the witness store was not read"], [], fix
    problems = [f"{f.robot_id}: {f.kind}: {f.message}" for f in w.findings][:5]
    problems += [f"not witnessed: {u}" for u in w.unmatched]
    if not ev.witness_key_given:
        problems.append("cosignatures not checked: no witness verifier key given")
    elif any(not b.cosignature_checked for b in w.bounds):
        problems.append("a cosignature does not verify under the witness key given")
    if not w.bounds:
        problems.append("no cosigned checkpoint in the root's witness/ store")
    found = [
        f"{b.robot_id}: {b.witness} cosigned through cycle {b.cycle} (tree size "
        f"{b.tree_size}) at {b.time}"
        for b in w.bounds
    ]
    return problems, found, fix


_GAP_KINDS = frozenset(
    ("undeclared_gap", "missing", "missing_segment", "truncated", "unsealed", "truncated_tail")
)


def _gaps(ev: RootEvidence, _clause: Clause) -> _Outcome:
    r = ev.report
    problems = [
        f"{f.robot_id} {f.segment}: {f.kind}: {f.message}"
        for f in r.findings
        if f.kind in _GAP_KINDS
    ][:8]
    declared = [n for n in r.notes if n.kind == "declared_gap"]
    found = [
        f"{r.cycles_valid} cycles in one chain per robot; {r.declared_dropped} cycles "
        f"declared dropped by the logger ({len(declared)} declared gaps)"
    ]
    return (
        problems,
        found,
        (
            "find where the cycles went (trace-audit verify ROOT); a logger "
            "declares what it drops, so an undeclared gap is lost data"
        ),
    )


def _chain(ev: RootEvidence, _clause: Clause) -> _Outcome:
    r = ev.report
    problems = [f"{f.robot_id} {f.segment}: {f.kind}: {f.message}" for f in r.findings][:8]
    if len(r.findings) > 8:
        problems.append(f"... {len(r.findings) - 8} more findings (trace-audit verify)")
    found = [
        f"{r.cycles_valid} of {r.cycles} cycles verify across {len(r.segments)} "
        f"segments of {len(r.robots)} robot(s)"
    ]
    return (
        problems,
        found,
        (
            "the root is not what its robots wrote: keep it as evidence and "
            "restore the segments from a verified copy"
        ),
    )


def _retention(ev: RootEvidence, clause: Clause) -> _Outcome:
    period = (clause.keep_days or 0) * DAY_NS
    keep = ev.keep
    problems: list[str] = []
    if keep is None:
        problems.append(
            f"no compliance profile adopted ({COMPLIANCE_NAME}): compact deletes verified "
            f"cold segments after {DEFAULT_RETENTION_NS // DAY_NS}d and summarises hot ones "
            f"after a day by default, below the {clause.keep_days}d asked"
        )
    elif keep.keep_ns < period:
        problems.append(
            f"the root keeps its records {keep.keep_ns // DAY_NS}d ({COMPLIANCE_NAME}), "
            f"below the {clause.keep_days}d asked"
        )
    elif clause.full_detail and keep.full_detail_ns < period:
        problems.append(
            f"the root allows warm summaries (lossy) of records younger than the "
            f"{clause.keep_days}d asked in full ({COMPLIANCE_NAME})"
        )
    cutoff = ev.newest_ns - period
    if clause.full_detail:
        problems += [
            f"{v.name}: summarised (warm) though it ends within {clause.keep_days}d of the "
            "newest record"
            for v in ev.versions
            if v.tier == "warm" and v.end_ns > cutoff
        ]
    deleted = [d for d in ev.deleted if d.end_ns > cutoff]
    problems += [
        f"{d.path}: deleted by retention though it ended within {clause.keep_days}d of the "
        "newest record"
        for d in deleted
    ]
    found = [
        f"adopted: {p.name} keeps {p.keep_days}d" + (" in full detail" if p.full_detail else "")
        for p in (keep.profiles if keep else ())
    ]
    found.append(f"{len(ev.deleted)} segment(s) deleted by retention so far")
    fix = f"trace-audit comply ROOT --profile {ev.profile} --adopt (compact then keeps the period)"
    if deleted or any(v.tier == "warm" and v.end_ns > cutoff for v in ev.versions):
        fix += "; restore the full segments from a verified copy"
    return problems, found, fix


def _safety_rules(ev: RootEvidence, _clause: Clause) -> _Outcome:
    problems: list[str] = []
    found: list[str] = []
    for robot, t in sorted(ev.safety.items()):
        if t.unchecked:
            cycle, t_ns = t.first_unchecked or (0, 0)
            problems.append(
                f"{robot}: {t.unchecked} of {t.decisions} decisions record no "
                f"safety-rule check (the first: cycle {cycle} at {show_instant(t_ns, t.clock)})"
            )
        rules = ", ".join(f"{name} ({failed} failed)" for name, failed in sorted(t.rules.items()))
        found.append(f"{robot}: {t.decisions} decisions; rules checked: {rules or 'none'}")
    return (
        problems,
        found,
        (
            "record each safety rule checked on the execution "
            "(ExecutionRecord.checks); trace-audit check judges STL rules "
            "over the log (docs/rules.md)"
        ),
    )


CHECKS: dict[CheckName, Callable[[RootEvidence, Clause], _Outcome]] = {
    "versions": _versions,
    "signed": _signed,
    "witnessed": _witnessed,
    "gaps": _gaps,
    "chain": _chain,
    "retention": _retention,
    "safety_rules": _safety_rules,
}
