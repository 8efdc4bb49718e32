"""One decision's ET, ET_partial, DR and TCS, by the metrics' own definitions."""

from __future__ import annotations

from trace_audit.chains import DecisionChains
from trace_audit.explanation.result import DecisionScores, SealCheck
from trace_audit.metrics import MetricsConfig, dr_problems, trust_score
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.gaps import continuity
from trace_runtime.records import TOPIC_ACTION

__all__ = ["decision_scores"]


def decision_scores(
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
    if chains.unknown:
        unread = sum(1 for f in chains.factors if f.unknown)
        problems.append(f"ET: unknown: {unread} factor(s) cite a recording that could not be read")
    return DecisionScores(
        et=chains.known_et,
        et_partial=chains.known_et_partial,
        fully_traceable=chains.fully_traceable,
        dr=0.0 if missing_dr else 1.0,
        tcs=None if chains.unknown else tcs,
        problems=tuple(problems),
        source="trace_audit.metrics definitions (docs/metrics.md), default TCS weights",
    )
