"""Re-run the policy on a logged run: does every logged decision and counterfactual hold?

For each cycle with a full belief and action record, the policy input is rebuilt from the
logged belief graph (``PolicyInput.from_nodes``) with the hysteresis state the log records
(the leaf taken in the previous cycle, from its action record's tree). Then:

- the logged command must be what the policy chooses on the logged values;
- each logged counterfactual must hold under ``do(factor = threshold)``, propagated to the
  factor's descendants through the logged edges and their rules (``sim.counterfactual.holds``).

A cycle whose graph lacks an edge a rule reads (an injected edge-write failure), or whose
previous cycle is not in the log (the hysteresis state is then unknown), cannot be re-run
from the log alone: it is counted as unverifiable, never as passing or failing.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sim.belief import missing_rule_edges
from sim.counterfactual import Found, holds
from sim.policy import LEAVES, PolicyInput, evaluate
from sim.runner import POLICY_VERSION, SimUsageError
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.reading.logset import open_log
from trace_runtime.records import TOPIC_ACTION, TOPIC_BELIEF


@dataclass(frozen=True, slots=True)
class _Node:
    id: str
    value: object


@dataclass(frozen=True, slots=True)
class Finding:
    """A logged decision or counterfactual that the policy does not reproduce."""

    cycle: int
    t_ns: int
    what: str
    """``decision`` or ``counterfactual``."""
    claim: str
    got: str

    def as_dict(self) -> dict[str, Any]:
        return {
            "cycle": self.cycle,
            "t_s": self.t_ns / 1e9,
            "what": self.what,
            "claim": self.claim,
            "got": self.got,
        }


@dataclass(slots=True)
class ReplayReport:
    """What re-running the policy on a log found."""

    path: Path
    cycles: int = 0
    decisions: int = 0
    counterfactuals: int = 0
    unverifiable: dict[str, int] = field(default_factory=dict)
    """Reason -> counterfactuals that could not be re-run from the log."""
    findings: list[Finding] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.findings

    def as_dict(self) -> dict[str, Any]:
        return {
            "path": str(self.path),
            "cycles": self.cycles,
            "decisions_checked": self.decisions,
            "counterfactuals_checked": self.counterfactuals,
            "unverifiable": self.unverifiable,
            "ok": self.ok,
            "findings": [f.as_dict() for f in self.findings],
        }


def _claim(cf: dict[str, Any]) -> str:
    return f"would {cf['would_select']} if {cf['factor']} {cf['comparison']} {cf['threshold']}"


def _taken_leaf(action: dict[str, Any] | None) -> str | None:
    if action is None or not action.get("tree"):
        return None
    path = action["tree"].get("taken_path") or []
    return path[-1] if path and path[-1] in LEAVES else None


def check_counterfactuals(
    path: str | Path, progress: Callable[[int], None] | None = None
) -> ReplayReport:
    """Re-run every logged decision and counterfactual of the log at ``path``.

    Only the simulator's own policy can be re-run, so a log another robot (or an earlier
    policy) wrote is refused with ``SimUsageError`` instead of being judged by rules it never
    followed."""
    log = open_log(path)
    policies = sorted({s.session.policy_version for s in log.segments})
    if policies != [POLICY_VERSION]:
        named = ", ".join(repr(p) for p in policies) or "none"
        raise SimUsageError(
            f"{path} was written by policy {named}; check-counterfactuals re-runs only the "
            f"simulator's policy {POLICY_VERSION!r} (trace-sim run writes such logs)"
        )
    report = ReplayReport(Path(path))
    prev_cycle: int | None = None
    prev_leaf: str | None = None
    for cycle in log.iter_cycles():
        report.cycles += 1
        if progress is not None and report.cycles % 1000 == 0:
            progress(report.cycles)
        belief = cycle.json(TOPIC_BELIEF)
        action = cycle.json(TOPIC_ACTION)
        # The run's first cycle (0) had no previous decision; otherwise the previous one
        # must be in the log for its leaf to be known.
        held_known = cycle.cycle == 0 or prev_cycle == cycle.cycle - 1
        held = prev_leaf if held_known else None
        prev_cycle, prev_leaf = cycle.cycle, _taken_leaf(action)
        if belief is None or action is None:
            continue
        _replay(report, cycle, belief, action, held_known=held_known, held=held)
    return report


def _replay(
    report: ReplayReport,
    cycle: Cycle,
    belief: dict[str, Any],
    action: dict[str, Any],
    *,
    held_known: bool,
    held: str | None,
) -> None:
    """Re-run one logged decision, then its counterfactuals, into ``report``; what the log
    alone cannot re-run is counted as unverifiable."""
    cfs = action.get("counterfactuals") or []
    if not held_known:
        _unverifiable(report, "previous cycle not in the log (hysteresis state unknown)", cfs)
        return
    nodes = [_Node(n["id"], n.get("value")) for n in belief["nodes"]]
    values = {n.id: n.value for n in nodes}
    edges = [(e["parent"], e["child"], e["rule"]) for e in belief["edges"]]
    try:
        inp = PolicyInput.from_nodes(nodes, held)
    except (KeyError, TypeError, ValueError):
        _unverifiable(report, "belief graph lacks a value the policy reads", cfs)
        return
    report.decisions += 1
    got = evaluate(inp, values).command
    if got != action["command"]:
        report.findings.append(Finding(cycle.cycle, cycle.t_ns, "decision", action["command"], got))
        return
    if missing_rule_edges(edges):
        _unverifiable(report, "belief edge missing from the log", cfs)
        return
    for cf in cfs:
        found = Found(cf["factor"], cf["comparison"], float(cf["threshold"]), cf["would_select"])
        report.counterfactuals += 1
        if cf["factor"] not in values or not holds(inp, values, found, edges):
            report.findings.append(
                Finding(cycle.cycle, cycle.t_ns, "counterfactual", _claim(cf), "does not hold")
            )


def _unverifiable(report: ReplayReport, reason: str, cfs: list[Any]) -> None:
    report.unverifiable[reason] = report.unverifiable.get(reason, 0) + len(cfs)
