"""The policy, its counterfactual prober and the rationale buffer, without a log."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from sim.belief import (
    RULE_BLOCKED,
    RULE_PED_RISK,
    PlanCache,
    intervene,
    intervention_plan,
    ped_risk,
)
from sim.counterfactual import BudgetExhaustedError, holds, probe
from sim.policy import (
    CONTINUE,
    REROUTE,
    SLOW,
    STOP,
    PolicyInput,
    choose,
    describe,
    evaluate,
    factors_of,
    score_alternatives,
)
from sim.records import RationaleBuffer

PED = PolicyInput(peds=(("ped_1", "ped_1.collision_risk", "ped_1.distance"),))


def _ped_close_values() -> dict[str, object]:
    return {"ped_1.collision_risk": 0.7, "ped_1.distance": 1.5, "aisle_blocked": 0.01}


def test_paper_example_stops_and_its_counterfactuals_respect_the_speed_limit() -> None:
    """Worker at 1.5 m, risk 0.70: STOP; would SLOW if d >= 2.0, and SLOW (not the paper's
    CONTINUE) if risk < 0.2: the worker is still within the 4 m slow zone that keeps the
    robot under the 0.5 m/s limit within 3 m of a person."""
    values = _ped_close_values()
    outcome = evaluate(PED, values)
    assert outcome.command == STOP
    assert outcome.path == ("root", "ped_in_path", "ped_close", "stop_ped")
    assert factors_of(outcome) == ["ped_1.collision_risk", "ped_1.distance"]
    assert factors_of(outcome, PED) == ["ped_1.collision_risk", "ped_1.distance", "aisle_blocked"]
    found = {
        (c.factor, c.comparison, c.threshold, c.would_select)
        for c in probe(PED, values, factors_of(outcome, PED))
    }
    assert ("ped_1.distance", ">=", 2.0, SLOW) in found
    assert ("ped_1.collision_risk", "<", 0.2, SLOW) in found
    far = {**values, "ped_1.distance": 5.0}
    found_far = {
        (c.factor, c.comparison, c.threshold, c.would_select)
        for c in probe(PED, far, factors_of(evaluate(PED, far), PED))
    }
    assert ("ped_1.collision_risk", "<", 0.2, CONTINUE) in found_far


def test_alternatives_score_below_the_choice_and_say_why() -> None:
    values = _ped_close_values()
    outcome = evaluate(PED, values)
    score, alts = score_alternatives(outcome, values)
    assert {a.command for a in alts} == {SLOW, REROUTE, CONTINUE}
    assert all(a.score < score for a in alts)
    slow = next(a for a in alts if a.command == SLOW)
    assert "ped_1.distance" in slow.rejected_because and "stop distance" in slow.rejected_because


def test_a_second_pedestrian_keeps_the_stop_so_no_distance_counterfactual_is_claimed() -> None:
    inp = PolicyInput(
        peds=(("a", "a.collision_risk", "a.distance"), ("b", "b.collision_risk", "b.distance"))
    )
    values: dict[str, object] = {
        "a.collision_risk": 0.7,
        "a.distance": 1.5,
        "b.collision_risk": 0.6,
        "b.distance": 1.6,
        "aisle_blocked": 0.0,
    }
    found = probe(inp, values, ["a.distance"])
    # Moving a away leaves b inside the stop distance: STOP stays; no SLOW counterfactual.
    assert all(c.would_select != SLOW for c in found)


def test_budget_cut_raises_instead_of_returning_a_partial_set() -> None:
    values = _ped_close_values()
    factors = factors_of(evaluate(PED, values))
    try:
        probe(PED, values, factors, budget=2)
    except BudgetExhaustedError:
        return
    raise AssertionError("probing finished within a budget of 2 evaluations")


_risk = st.floats(0.0, 1.0)
_dist = st.floats(0.0, 30.0)


@settings(max_examples=150, deadline=None)
@given(r1=_risk, d1=_dist, r2=_risk, d2=_dist, vr=_risk, ttc=st.floats(0.0, 99.0), blocked=_risk)
def test_every_counterfactual_holds_when_the_policy_is_rerun(  # noqa: PLR0917
    r1: float, d1: float, r2: float, d2: float, vr: float, ttc: float, blocked: float
) -> None:
    inp = PolicyInput(
        peds=(
            ("p1", "p1.collision_risk", "p1.distance"),
            ("p2", "p2.collision_risk", "p2.distance"),
        ),
        vehicles=(("f1", "f1.collision_risk", "f1.ttc"),),
    )
    values: dict[str, object] = {
        "p1.collision_risk": r1,
        "p1.distance": d1,
        "p2.collision_risk": r2,
        "p2.distance": d2,
        "f1.collision_risk": vr,
        "f1.ttc": ttc,
        "aisle_blocked": blocked,
    }
    outcome = evaluate(inp, values)
    for cf in probe(inp, values, factors_of(outcome)):
        assert cf.would_select != outcome.command
        assert holds(inp, values, cf), cf


def test_vehicle_branch_stops_when_close_and_reroutes_when_far() -> None:
    inp = PolicyInput(vehicles=(("f", "f.collision_risk", "f.ttc"),))
    assert (
        evaluate(inp, {"f.collision_risk": 0.8, "f.ttc": 2.0, "aisle_blocked": 0.0}).command == STOP
    )
    assert (
        evaluate(inp, {"f.collision_risk": 0.8, "f.ttc": 4.0, "aisle_blocked": 0.0}).command
        == REROUTE
    )
    assert (
        evaluate(inp, {"f.collision_risk": 0.1, "f.ttc": 4.0, "aisle_blocked": 0.0}).command
        == CONTINUE
    )


def test_rationale_buffer_truncates_text_and_factors_when_full() -> None:
    full = RationaleBuffer(1024)
    small = RationaleBuffer(30)
    for buf in (full, small):
        buf.add_text("pedestrian in path (ped_1.collision_risk 0.70 >= 0.20)")
        buf.add_factor({"node": "ped_1.collision_risk", "value": 0.7})
    assert not full.truncated and len(full.factors) == 1
    r = small.rationale()
    assert r["truncated"] is True
    assert r["factors"] == []
    assert len(r["text"].encode()) == 30


@settings(max_examples=200, deadline=None)
@given(values=st.lists(st.floats(0.0, 5.0), min_size=7, max_size=7))
def test_fast_choose_agrees_with_evaluate(values: list[float]) -> None:
    inp = PolicyInput(
        peds=(("a", "a.collision_risk", "a.distance"), ("b", "b.collision_risk", "b.distance")),
        vehicles=(("f", "f.collision_risk", "f.ttc"),),
    )
    keys = [
        "a.collision_risk",
        "a.distance",
        "b.collision_risk",
        "b.distance",
        "f.collision_risk",
        "f.ttc",
        "aisle_blocked",
    ]
    v: dict[str, object] = {
        k: x / 5.0 if "risk" in k or k == "aisle_blocked" else x
        for k, x in zip(keys, values, strict=True)
    }
    assert choose(inp, v) == evaluate(inp, v).command


def test_hysteresis_holds_a_slow_until_the_risk_drops_below_the_hold_level() -> None:
    """Risk hovering at 0.19 after a SLOW stays SLOW (hold 0.15) and the text says why; a
    fresh decision at 0.19 does not slow for the pedestrian in path."""
    values: dict[str, object] = {
        "ped_1.collision_risk": 0.19,
        "ped_1.distance": 5.0,
        "aisle_blocked": 0.0,
    }
    fresh = evaluate(PED, values)
    assert fresh.command == CONTINUE
    held = PolicyInput(peds=PED.peds, held="slow")
    outcome = evaluate(held, values)
    assert outcome.command == SLOW and outcome.path[-1] == "slow"
    assert any("hysteresis" in p for p in describe(outcome, values))
    assert choose(held, values) == SLOW
    assert evaluate(held, {**values, "ped_1.collision_risk": 0.14}).command == CONTINUE


def test_an_intervention_on_distance_moves_the_risk_through_the_graphs_rule() -> None:
    """do(distance = x) recomputes collision_risk from its rule: the counterfactual on the
    distance is then what the whole graph would give, not the tree's test alone."""
    edges = [
        ("ped_1.distance", "ped_1.collision_risk", RULE_PED_RISK),
        ("ped_1.intent", "ped_1.collision_risk", RULE_PED_RISK),
        ("ped_1.conflict", "ped_1.collision_risk", RULE_PED_RISK),
    ]
    values: dict[str, object] = {
        "ped_1.distance": 3.0,
        "ped_1.intent": "standing",
        "ped_1.conflict": 1.0,
        "ped_1.collision_risk": ped_risk(3.0, "standing", 1.0),
        "aisle_blocked": 0.0,
    }
    assert evaluate(PED, values).command == SLOW  # risk 0.59: pedestrian in path
    plan = intervention_plan("ped_1.distance", edges)
    moved = dict(values)
    intervene(moved, plan, "ped_1.distance", 9.0)
    assert moved["ped_1.collision_risk"] == ped_risk(9.0, "standing", 1.0) < 0.2
    found = probe(PED, values, ["ped_1.distance"], edges=edges)
    # Farther away the propagated risk falls under 0.2, beyond the 4 m slow zone: CONTINUE.
    up = [c for c in found if c.comparison in (">=", ">")]
    assert len(up) == 1 and up[0].would_select == CONTINUE and 5.0 < up[0].threshold < 6.0
    for cf in found:
        assert holds(PED, values, cf, edges)
    # Held fixed (no edges), the risk stays 0.59 at any distance: no CONTINUE is reachable.
    assert all(c.would_select != CONTINUE for c in probe(PED, values, ["ped_1.distance"]))


PARENTS = ("distance", "intent", "conflict")


def test_plan_cache_gives_the_plan_intervention_plan_gives_and_forgets_the_oldest_shape() -> None:
    """Remembered plans recompute the same descendants, per graph shape; a probe with the
    cache finds exactly the counterfactuals a probe without it finds."""
    shapes = [
        (
            *((f"ped_{k}.{s}", f"ped_{k}.collision_risk", RULE_PED_RISK) for s in PARENTS),
            ("corridor.clearance", "aisle_blocked", RULE_BLOCKED),
        )
        for k in range(3)
    ]
    cache = PlanCache(size=2)
    for edges in shapes:
        for node in (edges[0][0], "corridor.clearance", edges[1][0]):
            remembered = [child for child, _ in cache.plan(node, edges)]
            assert remembered == [child for child, _ in intervention_plan(node, edges)]
            assert cache.plan(node, edges) is cache.plan(node, edges)
    assert list(cache._by_edges) == shapes[1:]  # the oldest shape made room
    values: dict[str, object] = {
        "ped_0.distance": 3.0,
        "ped_0.intent": "standing",
        "ped_0.conflict": 1.0,
        "ped_0.collision_risk": ped_risk(3.0, "standing", 1.0),
        "corridor.clearance": 9.0,
        "aisle_blocked": 0.0,
    }
    ped = PolicyInput(peds=(("ped_0", "ped_0.collision_risk", "ped_0.distance"),))
    factors = ["ped_0.distance", "aisle_blocked", "ped_0.collision_risk"]
    plain = probe(ped, values, factors, edges=shapes[0])
    assert plain and probe(ped, values, factors, edges=shapes[0], plans=cache) == plain
