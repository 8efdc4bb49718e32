"""The paper's metrics applied to an explanation method's output (docs/metrics.md).

An explanation record is what a method would keep per decision: the action it explains, the
other commands with their scores, the factors it cites (each with the belief node it was
read from, when the method keeps that link), counterfactuals if it makes any, and the
stored payload whose size is its storage cost.

Scoring reuses the investigator's owners rather than a second definition:

- ET / ET_partial: each cited factor is walked by ``trace_audit.chains.trace_layers``
  against the logged belief, perception and sensor window of the decision's cycle, exactly
  as TRACE's own factors are. A cited factor without a link walks nowhere (depth 0 of 5).
- DR: the record is put in TRACE's action shape and judged by
  ``trace_audit.metrics.dr_problems``: action, alternatives, a rationale naming factors,
  counterfactuals present (or declared none-applicable).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import orjson

from trace_audit.chains import SensorWindow, trace_layers
from trace_audit.metrics import dr_problems

__all__ = [
    "Citation",
    "ExplanationRecord",
    "ExplanationScore",
    "as_action",
    "score_explanation",
]


@dataclass(frozen=True, slots=True)
class Citation:
    """One factor an explanation cites: an input feature (or token) and its weight."""

    feature: str
    weight: float
    node: str | None
    """The belief node the feature was read from (the documented link); None: no link."""


@dataclass(frozen=True, slots=True)
class ExplanationRecord:
    """What one method keeps about one decision."""

    method: str
    cycle: int
    t_ns: int
    command: str | None
    alternatives: tuple[tuple[str, float], ...]
    """Other commands with the method's score for each (e.g. class probabilities)."""
    citations: tuple[Citation, ...]
    counterfactuals: tuple[dict[str, Any], ...] = ()
    counterfactuals_none_applicable: bool = False
    stored: dict[str, Any] = field(default_factory=dict)
    """The per-decision payload the method must keep to be audited later."""
    seconds: float = 0.0
    """CPU time the method took to produce this explanation."""


@dataclass(frozen=True, slots=True)
class ExplanationScore:
    et: float
    et_partial: float
    dr: bool
    problems: tuple[str, ...]
    bytes: int
    citations: int


def as_action(record: ExplanationRecord) -> dict[str, Any]:
    """The record in the shape of a TRACE ``/trace/action`` message (JSON dict)."""
    return {
        "cycle": record.cycle,
        "t_ns": record.t_ns,
        "command": record.command,
        "alternatives": [
            {"command": c, "score": s, "rejected_because": ""} for c, s in record.alternatives
        ],
        "rationale": {
            "text": "",
            "factors": [{"node": c.node, "name": c.feature} for c in record.citations],
            "truncated": False,
        },
        "counterfactuals": list(record.counterfactuals),
        "counterfactuals_none_applicable": record.counterfactuals_none_applicable,
    }


def score_explanation(
    record: ExplanationRecord, belief: Any, perception: Any, window: SensorWindow
) -> ExplanationScore:
    """ET, ET_partial, DR and stored bytes of one explanation, against the logged cycle.

    ``window`` must hold the sensor messages of the record's cycle (and those before it that
    refs may point to), as for TRACE's own metrics.
    """
    action = as_action(record)
    chains = trace_layers(record.cycle, record.t_ns, action, belief, perception, window=window)
    problems = [f"ET: {chains.reason}"] if chains.reason else []
    for chain in chains.factors:
        missing = chain.missing
        if missing is not None:
            problems.append(f"ET: {chain.name}: {missing.level} missing ({missing.detail})")
    dr = dr_problems(action)
    return ExplanationScore(
        et=chains.et,
        et_partial=chains.et_partial,
        dr=not dr,
        problems=tuple(problems + [f"DR: {p}" for p in dr]),
        bytes=len(orjson.dumps(record.stored)),
        citations=len(record.citations),
    )
