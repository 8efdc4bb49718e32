"""Counterfactuals found by probing the policy, not by reading its thresholds.

For each factor of a decision, the prober intervenes on that one belief node the way
``do(node = x)`` does on a causal graph: the node is set, its descendants are recomputed
from it by the belief graph's own rules (``sim.belief.intervene``; moving a pedestrian's
distance moves its collision risk), every other node is held. It scans from the observed
value towards each end of the factor's domain and bisects the first bracket where the
command changes. The boundary is then snapped to two decimals
only if the policy confirms the snapped value. What is reported is therefore true of the
policy by construction:

- ``>= t`` / ``<= t``: re-running the policy with the factor at ``t`` selects ``would_select``;
- ``> t`` / ``< t``: it does so at ``t +/- STRICT_EPS`` (and not at ``t``).

Probing has a budget of policy evaluations. When it runs out the prober gives up and
returns nothing: a partial set of counterfactuals would look complete to an investigator.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass

from sim.belief import Plan, PlanCache, intervene, intervention_plan
from sim.policy import PolicyInput, choose
from trace_runtime.errors import TraceError

STRICT_EPS = 1e-6
DEFAULT_BUDGET = 400
_GRID = 4
_DOMAINS = {
    "distance": (0.0, 30.0, 0.002),
    "ttc": (0.0, 99.0, 0.002),
    "collision_risk": (0.0, 1.0, 0.0005),
    "aisle_blocked": (0.0, 1.0, 0.0005),
    "clearance": (0.0, 10.0, 0.002),
    "closing": (-5.0, 5.0, 0.002),
    "conflict": (0.0, 1.0, 0.0005),
}


class BudgetExhaustedError(TraceError):
    """The probing ran out of policy evaluations (caught inside ``sim``; a ``TraceError`` like
    every error the project raises on purpose)."""


@dataclass(slots=True)  # not frozen: ~4x cheaper to create
class Found:
    factor: str
    comparison: str
    threshold: float
    would_select: str


def domain_of(node: str) -> tuple[float, float, float]:
    """(low, high, tolerance) of a factor, by the node id's suffix."""
    return _DOMAINS[node.rsplit(".", 1)[-1]]


def probe(
    inp: PolicyInput,
    values: Mapping[str, object],
    factors: list[str],
    budget: int = DEFAULT_BUDGET,
    edges: Iterable[tuple[str, str, str]] = (),
    *,
    plans: PlanCache | None = None,
) -> list[Found]:
    """Counterfactuals for each numeric factor, in both directions; raise BudgetExhaustedError.

    ``edges`` are the belief graph's (parent, child, rule): an intervention on a factor is
    propagated to its descendants through them. Without edges nothing is propagated.
    ``plans`` remembers how, across calls (the plans are the same either way)."""
    spent = 0
    edge_list = tuple(edges)
    base_values = dict(values)
    v = dict(values)
    plan: Plan = []

    def run(node: str, x: float) -> str:
        nonlocal spent
        spent += 1
        if spent > budget:
            raise BudgetExhaustedError(f"counterfactual probing exceeded {budget} evaluations")
        intervene(v, plan, node, x)
        return choose(inp, v)

    def again(command: str) -> str:
        # A run of a (node, x) this search ran before: charged to the budget like any run,
        # but not run again. Its answer depends only on (node, x) and the base values: each
        # run sets the node and recomputes all of its descendants, and touches nothing else.
        nonlocal spent
        spent += 1
        if spent > budget:
            raise BudgetExhaustedError(f"counterfactual probing exceeded {budget} evaluations")
        return command

    spent = 1
    base = choose(inp, v)
    found: list[Found] = []
    for node in factors:
        current = values[node]
        if not isinstance(current, (int, float)) or isinstance(current, bool):
            continue
        if not edge_list:
            plan = []
        elif plans is not None:
            plan = plans.plan(node, edge_list)
        else:
            plan = intervention_plan(node, edge_list)
        lo_d, hi_d, tol = domain_of(node)
        c = float(current)
        for end in (hi_d, lo_d):
            hit = _search(run, again, node, c, end, tol=tol, base=base)
            if hit is not None:
                found.append(hit)
        v.update(base_values)
    return found


def _search(
    run: Callable[[str, float], str],
    again: Callable[[str], str],
    node: str,
    c: float,
    end: float,
    *,
    tol: float,
    base: str,
) -> Found | None:
    """Walk from ``c`` towards ``end`` for a value that changes the choice, then bisect to
    its threshold. ``again(answer)`` stands for a ``run`` of a value already run: the budget
    spent, and so where it runs out, is that of running it again."""
    if abs(end - c) <= tol:
        return None
    up = end > c
    prev = c
    flip: float | None = None
    gives = base
    for k in range(1, _GRID + 1):
        x = c + (end - c) * k / _GRID
        gives = run(node, x)
        if gives != base:
            flip = x
            break
        prev = x
    if flip is None:
        return None
    same, other = prev, flip
    while abs(other - same) > tol:
        mid = 0.5 * (same + other)
        got = run(node, mid)
        if got == base:
            same = mid
        else:
            other, gives = mid, got
    would = again(gives)  # ``other`` was run last as the flip or a midpoint
    snapped = round(other, 2)
    at_snapped: str | None = None
    if up:
        if snapped > c:
            at_snapped = run(node, snapped)
            if at_snapped == would:
                return Found(node, ">=", snapped, would)
        at_snapped = run(node, snapped) if at_snapped is None else again(at_snapped)
        if at_snapped == base and run(node, snapped + STRICT_EPS) == would:
            return Found(node, ">", snapped, would)
        return Found(node, ">=", other, would)
    if snapped < c and snapped >= 0.0:
        at_snapped = run(node, snapped)
        if at_snapped == would:
            return Found(node, "<=", snapped, would)
    at_snapped = run(node, snapped) if at_snapped is None else again(at_snapped)
    if at_snapped == base and run(node, snapped - STRICT_EPS) == would:
        return Found(node, "<", snapped, would)
    return Found(node, "<=", other, would)


def holds(
    inp: PolicyInput,
    values: Mapping[str, object],
    cf: Found,
    edges: Iterable[tuple[str, str, str]] = (),
) -> bool:
    """Re-run the policy under ``do(factor = threshold)`` (propagated through ``edges``):
    does it select ``would_select``?"""
    x = cf.threshold
    if cf.comparison == ">":
        x += STRICT_EPS
    elif cf.comparison == "<":
        x -= STRICT_EPS
    v = dict(values)
    edge_list = list(edges)
    plan = intervention_plan(cf.factor, edge_list) if edge_list else []
    intervene(v, plan, cf.factor, x)
    return choose(inp, v) == cf.would_select
