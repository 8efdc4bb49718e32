"""What one decision scores by the metrics' definitions, apart from the scan that feeds it.

Why it is not reconstructable (DR), why it fails integrity (from the one seal check), why a
factor is not traceable (ET), its trust score TCS(d), and the scenario it is grouped under.
``explain`` and the simulator's evaluation call these too, so a decision scores the same
everywhere.
"""

from __future__ import annotations

from trace_audit.chains import DecisionChains
from trace_audit.metrics.config import TCSWeights
from trace_runtime.encoding.seal_check import SealStatus
from trace_runtime.flags import split_flags

__all__ = [
    "NO_SCENARIO",
    "dr_problems",
    "et_problems",
    "integrity_problems",
    "scenario_of",
    "trust_score",
]

NO_SCENARIO = "(none)"
"""The group of a decision whose execution record names no scenario."""


def integrity_problems(status: SealStatus) -> list[str]:
    """Why a decision fails integrity, from the one seal check; [] when it holds."""
    if status.state == "unsealed":
        return ["not sealed"]
    problems = [f"{topic} does not match its seal digest" for topic in status.modified]
    problems += [f"{topic} is not named by the seal" for topic in status.extra]
    problems += [f"{topic} is named by the seal but missing" for topic in status.missing]
    problems += [
        f"sensor reading {reading} does not match the digest its evidence ref names"
        for reading in status.evidence_mismatch
    ]
    if status.state == "modified" and not problems:
        problems.append(status.detail)  # a malformed seal, or one naming another cycle
    if status.link == "broken":
        problems.append("hash chain broken: prev is not the previous seal's digest")
    return problems


def trust_score(
    weights: TCSWeights,
    *,
    et: float,
    et_partial: float,
    dr_ok: bool,
    continuity: float,
    intact: bool,
) -> float:
    """TCS(d): the weighted mean of ET, ET_partial, DR, continuity and integrity (docs/metrics.md);
    0 when integrity fails and the gate is on."""
    if not intact and weights.integrity_gate:
        return 0.0
    total = weights.et + weights.et_partial + weights.dr + weights.continuity + weights.integrity
    return (
        weights.et * et
        + weights.et_partial * et_partial
        + weights.dr * dr_ok
        + weights.continuity * continuity
        + weights.integrity * intact
    ) / total


def dr_problems(action: object) -> list[str]:
    """Why a decision is not reconstructable (DR = 0); [] when DR = 1. ``action`` is JSON."""
    if not isinstance(action, dict) or not action.get("command"):
        return ["action not logged"]
    problems: list[str] = []
    if not action.get("alternatives"):
        problems.append("no alternatives logged")
    rationale = action.get("rationale")
    if not isinstance(rationale, dict):
        problems.append("no rationale logged")
        return problems
    if rationale.get("truncated"):
        problems.append("rationale truncated")
    factors = rationale.get("factors")
    if not factors or not isinstance(factors, list):
        problems.append("rationale names no factors")
    if not action.get("counterfactuals") and not action.get("counterfactuals_none_applicable"):
        problems.append("no counterfactuals and not declared none-applicable")
    return problems


def et_problems(chains: DecisionChains) -> list[str]:
    """Why the decision is not fully traceable, one line per factor whose chain breaks."""
    if chains.reason:
        return [f"ET: {chains.reason}"]
    out: list[str] = []
    for factor in chains.factors:
        link = factor.missing
        if link is not None:
            label = f"{factor.node} ({factor.name})" if factor.name else factor.node
            out.append(
                f"ET: factor {label}: {link.level} missing ({link.detail}); "
                f"depth {factor.depth}/{factor.expected_depth}"
            )
    return out


def scenario_of(execution: object) -> str:
    """The scenario an execution record's ``scenario:NAME`` flag names, or ``(none)``."""
    if isinstance(execution, dict):
        return split_flags(execution.get("flags") or ())[1] or NO_SCENARIO
    return NO_SCENARIO
