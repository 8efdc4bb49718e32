"""The simulator end to end: logs read back through trace_runtime's reader."""

from __future__ import annotations

import hashlib
import math
from collections import Counter
from pathlib import Path
from typing import Any

import orjson
import pytest
from typer.testing import CliRunner

from sim import FaultRates, RunConfig, RunResult, parse_duration, read_truth, run
from sim.cli import app
from sim.replay import check_counterfactuals
from trace_runtime import Cycle, open_log

SCENARIO_FLAG = "scenario:"


def _cycles(result: RunResult) -> list[Cycle]:
    return list(open_log(result.out).iter_cycles())


def _scenario(cycle: Cycle) -> str:
    execution = cycle.execution
    assert execution is not None
    flags = [f for f in execution.flags if f.startswith(SCENARIO_FLAG)]
    assert len(flags) == 1
    return flags[0][len(SCENARIO_FLAG) :]


@pytest.fixture(scope="module")
def faulty(tmp_path_factory: pytest.TempPathFactory) -> RunResult:
    """The paper's run: five scenarios x 100 cycles, faults at the paper's rates."""
    out = tmp_path_factory.mktemp("faulty") / "run.mcap"
    return run(RunConfig(out=out, scenario="all", cycles=100, seed=3))


@pytest.fixture(scope="module")
def clean(tmp_path_factory: pytest.TempPathFactory) -> RunResult:
    out = tmp_path_factory.mktemp("clean")  # a log root
    return run(RunConfig(out=out, scenario="all", cycles=100, seed=5, faults=FaultRates.off()))


def test_same_seed_gives_identical_seal_digests(tmp_path: Path) -> None:
    def seals(name: str, seed: int) -> list[tuple[int, str]]:
        result = run(RunConfig(out=tmp_path / name, scenario="all", cycles=30, seed=seed))
        out = []
        for c in _cycles(result):
            seal = c.seal
            assert seal is not None
            out.append((seal.cycle, hashlib.sha256(c.payloads["/trace/seal"]).hexdigest()))
        return out

    first, second = seals("a.mcap", 11), seals("b.mcap", 11)
    assert first == second
    assert len(first) > 100
    assert seals("c.mcap", 12) != first


def test_all_runs_scenarios_in_order_with_continuous_cycles_and_time(clean: RunResult) -> None:
    cycles = _cycles(clean)
    assert [c.cycle for c in cycles] == list(range(500))
    assert [c.t_ns for c in cycles] == [k * 100_000_000 for k in range(500)]
    order = [_scenario(c) for c in cycles]
    expected = ["clear_path", "ped_crossing", "ped_close", "multi_ped", "forklift"]
    assert order == [name for name in expected for _ in range(100)]
    assert clean.dropped == 0
    assert read_truth(clean.truth) == []


def _node_values(cycle: Cycle) -> dict[str, Any]:
    belief = cycle.belief
    assert belief is not None
    return {n.id: n.value for n in belief.nodes}


def _entity_class(cycle: Cycle, node: str) -> str | None:
    belief = cycle.belief
    assert belief is not None
    entity = node.split(".", 1)[0]
    for n in belief.nodes:
        if n.id == entity and n.kind == "entity":
            return str(n.value)
    return None


@pytest.mark.parametrize("which", ["faulty", "clean"])
def test_ped_close_holds_a_stop_for_a_pedestrian_under_two_metres(
    which: str, request: pytest.FixtureRequest
) -> None:
    result: RunResult = request.getfixturevalue(which)
    stops = []
    for c in _cycles(result):
        if _scenario(c) != "ped_close" or c.action is None or c.action.command != "STOP":
            continue
        for f in c.action.rationale.factors:
            if f.node.endswith(".distance") and _entity_class(c, f.node) == "person":
                assert isinstance(f.value, float)
                if f.value < 2.0:
                    stops.append(c.cycle)
    assert len(stops) >= 30  # held, not a blip


@pytest.mark.parametrize("which", ["faulty", "clean"])
def test_forklift_causes_a_stop_or_reroute(which: str, request: pytest.FixtureRequest) -> None:
    result: RunResult = request.getfixturevalue(which)
    caused = [
        c.cycle
        for c in _cycles(result)
        if _scenario(c) == "forklift"
        and c.action is not None
        and c.action.command in ("STOP", "REROUTE")
        and any(_entity_class(c, f.node) == "forklift" for f in c.action.rationale.factors)
    ]
    assert caused


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4, 42])
def test_clear_path_never_stops_for_a_vehicle_or_a_person(seed: int, tmp_path: Path) -> None:
    """Only pallets stand beside the path: no STOP names a person or a vehicle, and no vehicle
    is ever believed on a collision course (seeds 0, 1, 2 and 42 once stopped for a pallet
    whose centroid slid along as the robot passed it, read as a moving forklift)."""
    result = run(RunConfig(out=tmp_path / "c.mcap", scenario="clear_path", cycles=100, seed=seed))
    commands: Counter[str] = Counter()
    for c in _cycles(result):
        assert c.action is not None
        commands[c.action.command] += 1
        if c.action.command == "STOP":
            classes = {_entity_class(c, f.node) for f in c.action.rationale.factors}
            assert not classes & {"person", "forklift"}, (c.cycle, classes)
        values = _node_values(c)
        assert all(
            values[f"{node}.collision_risk"] == 0.0
            for node, value in values.items()
            if value == "forklift" and f"{node}.collision_risk" in values
        ), c.cycle
    assert commands["CONTINUE"] > 80


def test_every_logged_decision_and_counterfactual_holds_when_the_policy_is_rerun(
    faulty: RunResult,
) -> None:
    """The replay (``trace-sim check-counterfactuals``) re-runs each one from the log."""
    report = check_counterfactuals(faulty.out)
    assert report.findings == []
    assert report.decisions > 400 and report.counterfactuals > 500


def _resolves(ref: Any, cycle: Cycle, by_key: dict[tuple[str, int], Any]) -> Any:
    if ref is None:
        return None
    msg = by_key.get((ref.topic, ref.log_time_ns))
    if msg is None or msg.sequence != ref.sequence:
        return None
    if hashlib.sha256(msg.data).hexdigest() != ref.digest:
        return None
    return msg


def test_ped_close_stop_chain_reaches_a_logged_lidar_cluster(clean: RunResult) -> None:
    """factor -> belief edges -> pedestrian entity -> LiDAR evidence -> /sensors/lidar cluster."""
    cycles = _cycles(clean)
    sensors = {(m.topic, m.log_time_ns): m for c in cycles for m in c.sensors}
    found = 0
    for c in cycles:
        action, belief, perception = c.action, c.belief, c.perception
        if _scenario(c) != "ped_close" or action is None or action.command != "STOP":
            continue
        assert belief is not None and perception is not None
        parents: dict[str, list[str]] = {}
        for e in belief.edges:
            parents.setdefault(e.child, []).append(e.parent)
        nodes = {n.id: n for n in belief.nodes}
        risk = next(f.node for f in action.rationale.factors if f.node.endswith("collision_risk"))
        ped = risk.split(".")[0]
        # risk <- distance <- pedestrian entity node
        assert f"{ped}.distance" in parents[risk]
        assert parents[f"{ped}.distance"] == [ped]
        assert nodes[ped].kind == "entity" and nodes[ped].entity == ped
        entity = next(e for e in perception.entities if e.id == ped)
        assert entity.cls == "person"
        lidar = [ev for ev in entity.evidence if ev.sensor == "lidar"]
        if not lidar:
            continue  # LiDAR down this cycle: camera evidence only
        msg = _resolves(lidar[0].ref, c, sensors)
        assert msg is not None and msg.topic == "/sensors/lidar"
        first, last = (int(v) for v in lidar[0].region.values)  # type: ignore[union-attr]
        clusters = orjson.loads(msg.data)["clusters"]
        assert any(cl["first"] == first and cl["last"] == last for cl in clusters)
        found += 1
    assert found >= 30


def test_injected_faults_are_exactly_what_the_log_shows(tmp_path: Path) -> None:
    rates = FaultRates(
        lidar_unavailable=0.05,
        camera_unavailable=0.1,
        evidence_corruption=0.08,
        edge_write_failure=0.08,
        rationale_truncation=0.08,
        counterfactual_timeout=0.08,
        audit_write_timeout=0.05,
    )
    result = run(RunConfig(out=tmp_path / "f.mcap", total_cycles=2000, seed=9, faults=rates))
    truth = read_truth(result.truth)
    cycles = {c.cycle: c for c in _cycles(result)}
    sensors = {(m.topic, m.log_time_ns): m for c in cycles.values() for m in c.sensors}
    by_kind: dict[str, list[dict[str, Any]]] = {}
    for line in truth:
        assert set(line) == {"cycle", "t_ns", "scenario", "kind", "detail"}
        by_kind.setdefault(line["kind"], []).append(line)

    def within(count: int, n: int, p: float) -> None:
        sd = math.sqrt(n * p * (1 - p))
        assert abs(count - n * p) <= 4.5 * sd + 1, (count, n, p)

    written = len(cycles)
    assert written + result.dropped == 2000
    # Whole-cycle write timeouts: the cycle is missing and the next seal counts it.
    lost = {t["cycle"] for t in by_kind["audit_write_timeout"]}
    within(len(lost), 2000, rates.audit_write_timeout)
    assert lost == set(range(2000)) - set(cycles)
    for n in lost:
        nxt = min(k for k in cycles if k > n) if any(k > n for k in cycles) else None
        if nxt is not None:
            seal = cycles[nxt].seal
            assert seal is not None and seal.dropped >= 1

    trunc = {t["cycle"] for t in by_kind["rationale_truncation"]}
    within(len(trunc), written, rates.rationale_truncation)
    assert trunc == {k for k, c in cycles.items() if c.action and c.action.rationale.truncated}

    timeouts = {t["cycle"] for t in by_kind["counterfactual_timeout"]}
    within(len(timeouts), written, rates.counterfactual_timeout)
    no_cf = {
        k
        for k, c in cycles.items()
        if c.action
        and not c.action.counterfactuals
        and not c.action.counterfactuals_none_applicable
    }
    assert timeouts == no_cf

    edges = by_kind["edge_write_failure"]
    within(len(edges), written, rates.edge_write_failure)
    for t in edges:
        belief = cycles[t["cycle"]].belief
        assert belief is not None
        parent, child = t["detail"]["edge"]
        assert not any(e.parent == parent and e.child == child for e in belief.edges)

    corrupted = by_kind["evidence_corruption"]
    entity_draws = sum(len(c.perception.entities) for c in cycles.values() if c.perception)
    within(len(corrupted), entity_draws, rates.evidence_corruption)
    bad = {(t["cycle"], t["detail"]["entity"]) for t in corrupted}
    for k, c in cycles.items():
        assert c.perception is not None
        for e in c.perception.entities:
            resolved = [_resolves(ev.ref, c, sensors) is not None for ev in e.evidence]
            if (k, e.id) in bad:
                assert not any(resolved)
            else:
                assert all(resolved), (k, e.id)

    down = Counter(t["detail"]["sensor"] for t in by_kind["sensor_unavailable"])
    within(down["lidar"], written, rates.lidar_unavailable)
    within(down["camera"], written, rates.camera_unavailable)
    assert result.faults == {k: len(v) for k, v in by_kind.items()}


def test_faults_off_injects_nothing(clean: RunResult) -> None:
    for c in _cycles(clean):
        assert c.action is not None and c.perception is not None
        assert not c.action.rationale.truncated
        assert c.action.counterfactuals or c.action.counterfactuals_none_applicable
        assert c.perception.sensors_unavailable == []


def test_duration_parses_to_ten_hertz_cycles() -> None:
    assert parse_duration("24h") == 864_000
    assert parse_duration("90s") == 900
    assert parse_duration("1.5m") == 900


def test_cli_run_json_and_scenarios(tmp_path: Path) -> None:
    runner = CliRunner()
    listed = runner.invoke(app, ["scenarios", "--json"])
    assert listed.exit_code == 0
    assert [s["name"] for s in orjson.loads(listed.stdout)] == [
        "clear_path",
        "ped_crossing",
        "ped_close",
        "multi_ped",
        "forklift",
    ]
    out = tmp_path / "cli.mcap"
    res = runner.invoke(
        app,
        [
            "run",
            "--scenario",
            "ped_close",
            "--cycles",
            "12",
            "--out",
            str(out),
            "--faults",
            "off",
            "--json",
        ],
    )
    assert res.exit_code == 0, res.output
    summary = orjson.loads(res.stdout)
    assert summary["cycles"] == 12 and summary["commands"].get("STOP", 0) >= 8
    assert Path(summary["truth"]).exists()


@pytest.mark.parametrize(
    ("args", "code"),
    [
        (["run", "--scenario", "nope"], 2),
        (["run", "--cycles", "0"], 2),
        (["run", "--faults", "maybe"], 2),
        (["run", "--duration", "soon"], 2),
    ],
)
def test_cli_usage_errors_exit_2_with_one_line(args: list[str], code: int, tmp_path: Path) -> None:
    res = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "x.mcap")])
    assert res.exit_code == code
    assert res.stderr.startswith("trace-sim: ") and res.stderr.count("\n") == 1


def test_cli_unwritable_output_exits_4_as_trace_audit_does(tmp_path: Path) -> None:
    """An --out the process cannot write (a folder that cannot be made: its parent is a
    regular file, which refuses root as well) is trace-audit's "cannot write", exit 4."""
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    res = CliRunner().invoke(app, ["run", "--out", str(blocker / "run.mcap"), "--cycles", "1"])
    assert res.exit_code == 4
    assert res.stderr.startswith("trace-sim: cannot write") and res.stderr.count("\n") == 1


def test_with_faults_off_at_most_2_percent_of_cycles_fail_a_compliance_check(
    clean: RunResult,
) -> None:
    """The policy enforces the monitor's rules itself, so a failed check is an anomaly."""
    cycles = _cycles(clean)
    failed = [
        c.cycle
        for c in cycles
        if c.execution is not None and any(not ch.passed for ch in c.execution.checks)
    ]
    assert len(cycles) == 500
    assert len(failed) <= 0.02 * len(cycles), failed


@pytest.mark.parametrize("seed", [1, 6, 9])
def test_forklift_scenario_exercises_the_vehicle_branch_with_a_logged_turn(
    seed: int, tmp_path: Path
) -> None:
    """At least 10% of cycles are not CONTINUE, the vehicle branch decides some of them, and
    the execution record shows the U-turn a REROUTE starts (intended yaw rate 0.6 rad/s)."""
    result = run(
        RunConfig(
            out=tmp_path / "f.mcap",
            scenario="forklift",
            cycles=100,
            seed=seed,
            faults=FaultRates.off(),
        )
    )
    cycles = _cycles(result)
    commands = Counter(c.action.command for c in cycles if c.action is not None)
    assert commands["CONTINUE"] <= 90, commands
    leaves = {c.action.tree.taken_path[-1] for c in cycles if c.action and c.action.tree}
    assert leaves & {"stop_vehicle", "reroute_vehicle"}, leaves
    turning = [
        c.cycle
        for c in cycles
        if c.execution is not None
        and "u_turn" in c.execution.flags
        and c.execution.intended.angular == 0.6
    ]
    assert len(turning) >= 20, turning
