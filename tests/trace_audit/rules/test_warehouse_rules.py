"""The shipped warehouse rules (docs/rules/warehouse.toml) on the simulator's robot: they
hold on a faults-off run, and a policy fault injected into the simulator's decision step
(a policy blind to people beyond 1 m) breaks them at exactly the cycles where the logged
decisions broke them, found here from the log's records by hand, not by the checker."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import pytest

import sim.decision
from sim.faults import FaultRates
from sim.policy import CONTINUE, PolicyInput, evaluate
from sim.runner import RunConfig, run
from trace_audit.rules import CheckResult, Outcome, RuleResult, check_rules, read_rules
from trace_runtime.reading.logset import open_log

REPO = Path(__file__).resolve().parents[3]
RULES = REPO / "docs" / "rules" / "warehouse.toml"
CYCLES = 3000
BLIND_BEYOND_M = 1.0


def _blind_policy(inp: PolicyInput, values: Any) -> Any:
    """The policy as written, but shown only the people within ``BLIND_BEYOND_M``."""
    near = tuple(p for p in inp.peds if float(values[p[2]]) < BLIND_BEYOND_M)
    return evaluate(dataclasses.replace(inp, peds=near), values)


def _simulate(out: Path) -> None:
    run(RunConfig(out=out, total_cycles=CYCLES, seed=1, faults=FaultRates.off()))


def _rules(result: CheckResult) -> dict[str, RuleResult]:
    (robot,) = result.robots
    return {rule.rule: rule for rule in robot.rules}


def _violated_cycles(rule: RuleResult) -> set[int]:
    return {c for v in rule.violations for c in range(v.first_cycle, v.last_cycle + 1)}


def _logged(root: Path) -> list[tuple[int, float, str, float]]:
    """(cycle, nearest person in m, command, |actual linear| in m/s) of each cycle, read
    straight from the records: a person entity's distance is its belief node
    ``<id>.distance``."""
    rows = []
    for cycle in open_log(root).iter_cycles():
        perception = cycle.json("/trace/perception")
        belief = cycle.json("/trace/belief")
        values = {n["id"]: n["value"] for n in belief["nodes"]}
        people = [e["id"] for e in perception["entities"] if e["class"] == "person"]
        nearest = min((values[f"{p}.distance"] for p in people), default=float("inf"))
        command = cycle.json("/trace/action")["command"]
        speed = abs(cycle.json("/trace/execution")["actual"]["linear"])
        rows.append((cycle.cycle, nearest, command, speed))
    return rows


def test_the_warehouse_rules_hold_on_a_faults_off_run(tmp_path: Path) -> None:
    _simulate(tmp_path / "run")
    rules = _rules(check_rules(tmp_path / "run", read_rules(RULES)))
    assert len(rules) == 6
    for name, rule in rules.items():
        assert rule.outcome is Outcome.SATISFIED, name
        assert rule.robustness is not None and rule.robustness > 0, name
        assert rule.decidable_cycles > 0.99 * CYCLES, name


def test_a_policy_blind_to_people_breaks_them_where_the_log_shows(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(sim.decision, "evaluate", _blind_policy)
    root = tmp_path / "blind"
    _simulate(root)
    rules = _rules(check_rules(root, read_rules(RULES)))
    logged = _logged(root)
    assert len(logged) == CYCLES

    # never CONTINUE with a person inside 4 m
    expected = {c for c, near, command, _ in logged if near < 4.0 and command == CONTINUE}
    assert expected, "the fault never showed; the test proves nothing"
    assert rules["slow_near_people"].outcome is Outcome.VIOLATED
    assert _violated_cycles(rules["slow_near_people"]) == expected

    # the nearest person always at least 0.5 m away
    expected = {c for c, near, _, _ in logged if near < 0.5}
    assert expected
    assert _violated_cycles(rules["separation"]) == expected
    assert rules["separation"].robustness == pytest.approx(
        min(near for _, near, _, _ in logged) - 0.5
    )

    # inside 2 m: not CONTINUE, and at most 0.55 m/s within 1 s (10 cycles); the last
    # second of the log cannot decide "within 1 s"
    speeds = [speed for *_, speed in logged]
    horizon = 10
    expected = {
        c
        for i, (c, near, command, _) in enumerate(logged[:-horizon])
        if near < 2.0 and (command == CONTINUE or min(speeds[i : i + horizon + 1]) > 0.55)
    }
    assert expected
    assert _violated_cycles(rules["person_stop_distance"]) == expected

    # each violation names the decision in force and the command that explains it
    first = rules["slow_near_people"].violations[0]
    assert first.command == CONTINUE
    assert first.explain == (
        f"trace-audit explain {root} --cycle {first.first_cycle} --robot amr-01"
    )


def test_rtamt_alone_gives_the_same_answer(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sim.decision, "evaluate", _blind_policy)
    root = tmp_path / "blind"
    run(RunConfig(out=root, total_cycles=600, seed=2))  # faults on: gaps and missing sensors
    rules = read_rules(RULES)
    assert check_rules(root, rules, engine="rtamt") == check_rules(root, rules)
