"""Layer 3 for one cycle: the choice, the scored alternatives, the counterfactuals and the
rationale, remembered per policy input.

All of it is a pure function of the belief graph's node values (the nodes the policy reads,
and the ones an intervention propagates from: conflicts, intents, closing speeds, the
clearance), of which nodes those are, and of the leaf held from the previous cycle. A
robot waiting in a clear aisle, or behind a worker who stands still, sees the same input
cycle after cycle: the decision is then taken from a small cache instead of being
re-derived, probes included. The counterfactuals stay true of the policy by construction:
they are the prober's answer for exactly this input. Faults that act on one cycle (a cut
probing budget, a short rationale buffer) are applied by the caller on top.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from sim.belief import BeliefGraph, PlanCache
from sim.counterfactual import DEFAULT_BUDGET, BudgetExhaustedError, Found, probe
from sim.policy import Outcome, PolicyInput, describe, evaluate, factors_of, score_alternatives
from sim.records import (
    RATIONALE_CAPACITY,
    RationaleBuffer,
    alternative_records,
    counterfactual_records,
    write_rationale,
)

CACHE_SIZE = 512


@dataclass(slots=True)
class Decision:
    """What layer 3 derives from one policy input (records as the logger takes them)."""

    outcome: Outcome
    factors: list[str]
    score: float
    alternatives: list[dict[str, Any]]
    counterfactuals: list[dict[str, Any]] | None
    """None: probing ran out of its budget (then nothing is claimed)."""
    phrases: list[str]
    rationale: dict[str, Any]
    """Written into a buffer of ``RATIONALE_CAPACITY`` bytes."""


class Decider:
    """Derives decisions, remembering the last ``CACHE_SIZE`` distinct policy inputs."""

    def __init__(self, size: int | None = None) -> None:
        self._size = CACHE_SIZE if size is None else size
        self._cache: dict[tuple[PolicyInput, tuple[Any, ...]], Decision] = {}
        self.plans = PlanCache()
        """Intervention plans, shared by every probe of this robot's graphs."""
        self.hits = 0
        self.misses = 0

    def decide(
        self, graph: BeliefGraph, held: str | None = None
    ) -> tuple[PolicyInput, dict[str, Any], Decision]:
        """The policy input and node values of ``graph``, and the decision on them, with
        ``held`` the leaf taken in the previous cycle."""
        values: dict[str, Any] = {n.id: n.value for n in graph.nodes}
        inp = PolicyInput.from_nodes(graph.nodes, held)
        read = tuple(values.get(n) for n in _decisive_nodes(inp))
        key = (inp, read)
        decision = self._cache.get(key)
        if decision is not None:
            self.hits += 1
            return inp, values, decision
        self.misses += 1
        decision = derive(inp, values, graph, self.plans)
        if self._size > 0 and _shareable(read):
            if len(self._cache) >= self._size:
                del self._cache[next(iter(self._cache))]  # the oldest entry
            self._cache[key] = decision
        return inp, values, decision


def _shareable(read: tuple[Any, ...]) -> bool:
    """Whether inputs equal to ``read`` are the same input: equal values can print
    differently (1 and 1.0, 0.0 and -0.0), and the rationale quotes them."""
    return all(
        type(x) is str or (type(x) is float and (x != 0.0 or math.copysign(1.0, x) > 0))
        for x in read
    )


def _decisive_nodes(inp: PolicyInput) -> list[str]:
    """Every node the decision depends on: what the tree reads, and what an intervention on
    a factor recomputes its descendants from (``sim.belief.RULES``' parents)."""
    nodes = []
    for e, risk, distance in inp.peds:
        nodes += [risk, distance, f"{e}.intent", f"{e}.conflict"]
    for e, risk, ttc in inp.vehicles:
        nodes += [risk, ttc, f"{e}.distance", f"{e}.closing", f"{e}.conflict"]
    nodes += [inp.aisle, "corridor.clearance"]
    return nodes


def graph_edges(graph: BeliefGraph) -> list[tuple[str, str, str]]:
    """(parent, child, rule) of each edge: what an intervention propagates through."""
    return [(e.parent, e.child, e.rule) for e in graph.edges]


def derive(
    inp: PolicyInput,
    values: dict[str, Any],
    graph: BeliefGraph,
    plans: PlanCache | None = None,
) -> Decision:
    """Evaluate the policy, score the alternatives, probe (with ``plans`` remembered
    across calls), and write the rationale."""
    outcome = evaluate(inp, values)
    factors = factors_of(outcome, inp)
    score, alternatives = score_alternatives(outcome, values)
    found: list[Found] | None
    try:
        found = probe(inp, values, factors, DEFAULT_BUDGET, graph_edges(graph), plans=plans)
    except BudgetExhaustedError:
        found = None
    phrases = describe(outcome, values)
    buffer = RationaleBuffer(RATIONALE_CAPACITY)
    write_rationale(buffer, phrases, outcome.tests, outcome.command, graph, factors=factors)
    return Decision(
        outcome=outcome,
        factors=factors,
        score=score,
        alternatives=alternative_records(alternatives),
        counterfactuals=None if found is None else counterfactual_records(found),
        phrases=phrases,
        rationale=buffer.rationale(),
    )
