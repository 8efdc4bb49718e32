"""explain: the decision in force at t, its reasons, chains, causal graph, seal and history."""

from __future__ import annotations

import json
import logging
from itertools import pairwise
from pathlib import Path

import networkx as nx
import orjson
import pytest
from typer.testing import CliRunner

from tests.trace_audit.conftest import (
    DEFAULT_SCRIPT,
    PERIOD_NS,
    T0_NS,
    rewrite_segment,
    stretch,
    t_ns,
    t_s,
    write_log,
)
from tests.trace_audit.in_flight import cut_in_flight
from trace_audit.causal import (
    causal_graph,
    causal_graph_data,
    graph_data,
    read_decision,
    tree_graph,
    tree_graph_data,
)
from trace_audit.chains import trace_cycle
from trace_audit.cli import app
from trace_audit.explanation import explain, find_cycle
from trace_audit.jsonout import to_jsonable
from trace_runtime import AuditLogger, LoggerConfig, RawMessage, open_log
from trace_runtime.errors import TimeOutOfRangeError, UsageError
from trace_runtime.records import TOPIC_ACTION, TOPIC_SEAL, DecisionTree, TreeEdge, TreeNode
from trace_runtime.testing import synthetic_cycle
from trace_runtime.tiers import refresh_catalog


def _graph(result: object) -> nx.DiGraph:
    data = result.graph  # type: ignore[attr-defined]
    g = nx.DiGraph()
    for node in data["nodes"]:
        g.add_node(node["id"], **{k: v for k, v in node.items() if k != "id"})
    for edge in data["edges"]:
        g.add_edge(edge["source"], edge["target"], **edge)
    return g


def test_stop_for_a_close_pedestrian_reads_like_the_paper(sample_log: Path) -> None:
    r = explain(sample_log, t=t_ns(45))
    d = r.decision
    assert (r.cycle, d.command) == (45, "STOP")
    assert d.rationale == "Pedestrian detected at 1.5m with collision risk 0.70."
    assert [(f.name, f.value) for f in d.factors] == [("distance", 1.5), ("collision_risk", 0.7)]
    assert [a.command for a in d.alternatives] == ["SLOW", "REROUTE", "CONTINUE"]
    assert all(a.rejected_because for a in d.alternatives)
    assert [c.text for c in d.counterfactuals] == [
        "would SLOW if distance >= 2.0 m",
        "would CONTINUE if collision_risk < 0.2",
    ]
    assert d.tree is not None
    assert d.tree.taken_path == ("root", "ped", "stop") and not d.tree.problems
    assert r.scores.et == 1.0 and r.scores.et_partial == 1.0 and not r.scores.problems
    assert r.seal.verified and r.seal.prev_cycle == 44


def test_causal_graph_runs_from_the_lidar_reading_to_the_action(sample_log: Path) -> None:
    g = _graph(explain(sample_log, t=t_ns(45)))
    sensor = f"sensor:/sensors/lidar@{T0_NS + 45 * PERIOD_NS}"
    chain = [
        sensor,
        "evidence:ped_1:0",
        "entity:ped_1",
        "belief:ped_1",
        "belief:ped_1.distance",
        "belief:collision_risk",
        "action",
    ]
    assert all(g.has_edge(u, v) for u, v in pairwise(chain))
    assert g.nodes["entity:ped_1"]["label"] == "person 0.92 (ped_1)"
    assert g.nodes["evidence:ped_1:0"]["label"] == "lidar beams [10, 13] w=0.80"
    assert all(g.edges[u, v]["documented"] for u, v in g.edges)
    assert g.edges["belief:ped_1.distance", "belief:collision_risk"]["rule"] == "ttc_risk"
    # both factors feed the action; the shared edges name both factor chains
    assert set(g.predecessors("action")) == {"belief:ped_1.distance", "belief:collision_risk"}
    assert set(g.edges["entity:ped_1", "belief:ped_1"]["factors"]) == {
        "ped_1.distance",
        "collision_risk",
    }


def test_a_null_evidence_ref_is_shown_missing_not_skipped(sample_log: Path) -> None:
    r = explain(sample_log, t=t_ns(82))  # the ped_close stretch logged with null refs
    assert r.decision.command == "STOP"
    assert r.scores.et == 0.0 and 0 < r.scores.et_partial < 1
    g = _graph(r)
    missing = [(u, v) for u, v, data in g.edges(data=True) if not data["documented"]]
    levels = {g.edges[e]["level"] for e in missing}
    assert levels == {"evidence_ref", "sensor_reading"}
    # the evidence item exists (sensor, region), only its link to the reading is gone
    assert ("evidence:ped_1:0", "entity:ped_1") in missing
    placeholder = next(u for u, v in missing if v == "evidence:ped_1:0")
    assert g.nodes[placeholder]["missing"]
    assert any("evidence_ref" in p for p in r.scores.problems)


def test_a_missing_belief_edge_breaks_the_chain_at_the_belief_path(tmp_path: Path) -> None:
    log = write_log(tmp_path / "r.mcap", [stretch("ped_close", 3, "no_edge")])
    r = explain(log, t=t_ns(1))
    chains = {c.node: c for c in r.chains.factors}
    assert chains["ped_1.distance"].traceable
    risk = chains["collision_risk"]
    assert (risk.depth, risk.expected_depth) == (1, 5)
    g = _graph(r)
    placeholder = "missing:belief_path:belief:collision_risk"
    assert g.nodes[placeholder]["missing"]
    assert not g.edges[placeholder, "belief:collision_risk"]["documented"]
    assert r.scores.et == 0.5


def test_time_between_cycles_gives_the_cycle_before_and_how_far(sample_log: Path) -> None:
    r = explain(sample_log, t="104.53")
    assert r.cycle == 45 and r.offset_ns == 30_000_000 and not r.stale


def test_relative_time_and_cycle_number_find_the_same_decision(sample_log: Path) -> None:
    by_abs = explain(sample_log, t=t_ns(45))
    by_rel = explain(sample_log, t="+4.5")
    by_cycle = explain(sample_log, cycle=45)
    assert by_abs.cycle == by_rel.cycle == by_cycle.cycle == 45
    assert by_cycle.offset_ns == 0 and by_cycle.query_t_ns is None


def test_time_outside_the_log_names_the_range(sample_log: Path) -> None:
    with pytest.raises(TimeOutOfRangeError, match=r"\[100.000 s, 109.900 s\]"):
        explain(sample_log, t="99.9")
    with pytest.raises(TimeOutOfRangeError):
        explain(sample_log, t="+60")


def test_exactly_one_of_time_and_cycle(sample_log: Path) -> None:
    with pytest.raises(UsageError):
        explain(sample_log)
    with pytest.raises(UsageError):
        explain(sample_log, t="+1", cycle=3)
    with pytest.raises(UsageError, match=r"cycle 500 is not in this log \(cycles 0..99\)"):
        explain(sample_log, cycle=500)


def test_held_since_points_to_the_cycle_that_began_the_action(sample_log: Path) -> None:
    held = explain(sample_log, t=t_ns(55)).held
    assert (held.since_cycle, held.cycles, held.bound) == (40, 16, "change")
    assert (held.previous, held.previous_cycle, held.at_least) == ("SLOW", 39, False)


def test_held_since_is_bounded_and_says_at_least(sample_log: Path) -> None:
    held = explain(sample_log, t=t_ns(55), lookback_s=0.5).held
    assert held.bound == "lookback" and held.at_least
    assert held.since_cycle == 50 and held.previous is None
    from_start = explain(sample_log, t=t_ns(20)).held
    assert (from_start.since_cycle, from_start.bound) == (0, "log_start")


def test_a_gap_before_t_is_reported_stale_and_the_seal_counts_the_drop(tmp_path: Path) -> None:
    log = write_log(tmp_path / "g.mcap", [stretch("clear", 20)], skip=lambda i: 8 <= i < 12)
    r = explain(log, t=t_ns(10))
    assert r.cycle == 7 and r.stale
    after = explain(log, t=t_ns(12))
    assert after.seal.dropped_before == 4 and after.seal.verified
    assert after.seal.prev_cycle == 7


def test_a_changed_payload_fails_the_seal(sample_log: Path, tmp_path: Path) -> None:
    def mutate(msg: RawMessage) -> bytes:
        if msg.topic == TOPIC_ACTION and msg.sequence == 45:
            return msg.data.replace(b'"STOP"', b'"CONTINUE"', 1)
        return msg.data

    tampered = rewrite_segment(sample_log, tmp_path / "t.mcap", mutate)
    r = explain(tampered, t=t_ns(45))
    assert r.decision.command == "CONTINUE"
    assert not r.seal.verified and r.seal.mismatched == (TOPIC_ACTION,)
    assert r.seal.prev_ok  # the chain itself is intact
    assert explain(tampered, t=t_ns(44)).seal.verified


def test_a_removed_seal_breaks_the_next_link(sample_log: Path, tmp_path: Path) -> None:
    def mutate(msg: RawMessage) -> bytes | None:
        if msg.topic == TOPIC_SEAL and msg.sequence == 44:
            return None
        return msg.data

    tampered = rewrite_segment(sample_log, tmp_path / "t.mcap", mutate)
    r = explain(tampered, t=t_ns(45))
    assert r.seal.digests_ok and r.seal.prev_ok is False and r.seal.prev_cycle == 43
    assert any("prev does not match" in p for p in r.seal.problems)


def test_first_cycle_of_a_later_segment_links_to_the_previous_segment(tmp_path: Path) -> None:
    root = write_log(tmp_path / "root", max_segment_s=3.0)
    log = open_log(root)
    assert len(log.segments) >= 3
    first = log.segments[1].session.first_cycle
    r = explain(log, cycle=first)
    assert r.seal.verified and r.seal.prev_cycle == first - 1
    # only the later segment present: the link is checked against its recorded prev_seal
    alone = explain(log.segments[1].path, cycle=first)
    assert alone.seal.verified and alone.seal.prev_cycle is None
    assert "prev_seal" in alone.seal.prev_source


def test_a_crashed_segment_is_recovered_and_said_so(
    crashed_log: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.WARNING, logger="trace_runtime"):
        r = explain(crashed_log, t=t_ns(45))
    assert r.recovered and r.decision.command == "STOP" and r.seal.verified
    assert sum("no footer" in m for m in caplog.messages) == 1


def test_refs_to_an_earlier_cycles_reading_resolve_through_the_window(tmp_path: Path) -> None:
    log = write_log(
        tmp_path / "r.mcap", [stretch("ped_close", 3), stretch("ped_close", 3, "old_ref")]
    )
    r = explain(log, t=t_ns(4))
    assert r.scores.et == 1.0  # the reading of cycle 3 is in the sensor window
    alone = explain(log, t=t_ns(4), sensor_window=0)
    assert alone.scores.et == 0.0
    assert {c.missing.level for c in alone.chains.factors if c.missing} == {"sensor_reading"}
    g = _graph(alone)
    sensor = f"sensor:/sensors/lidar@{t_ns(3)}"
    assert g.nodes[sensor]["missing"] and not g.edges[sensor, "evidence:ped_1:0"]["documented"]


def test_graph_and_tree_from_a_cycle(sample_log: Path) -> None:
    log = open_log(sample_log)
    cycle = log.cycle_at(t_ns(45))
    alone = trace_cycle(cycle)
    assert alone.et == 1.0  # the fixture's refs point into the same cycle
    decision = read_decision(cycle)
    g = causal_graph(cycle, alone, decision)
    assert g.graph["command"] == "STOP"
    assert decision.tree is not None
    t = tree_graph(decision.tree)
    assert [n for n, taken in t.nodes(data="taken") if taken] == ["root", "ped", "stop"]


@pytest.mark.parametrize("second", [45, 82, 1])
def test_graph_data_without_networkx_is_the_networkx_graphs_data(
    sample_log: Path, tmp_path: Path, second: int
) -> None:
    """explain builds its graphs without networkx; the data (order included) is what a
    networkx DiGraph built by the same calls gives: a documented chain, null evidence refs
    (placeholders), and a missing belief edge."""
    path = sample_log
    if second == 1:
        path = write_log(tmp_path / "r.mcap", [stretch("ped_close", 3, "no_edge")])
    cycle = open_log(path).cycle_at(t_ns(second))
    chains = trace_cycle(cycle)
    decision = read_decision(cycle)
    data = causal_graph_data(cycle, chains, decision)
    assert data == graph_data(causal_graph(cycle, chains, decision))
    assert orjson.dumps(data) == orjson.dumps(graph_data(causal_graph(cycle, chains, decision)))
    assert any(not e["documented"] for e in data["edges"]) == (second != 45)
    if decision.tree is not None:
        tree = tree_graph_data(decision.tree)
        assert orjson.dumps(tree) == orjson.dumps(graph_data(tree_graph(decision.tree)))


def test_explain_does_not_import_networkx(sample_log: Path) -> None:
    """networkx is ~50-120 ms of start-up; explain's graphs are plain data."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from trace_audit.explanation import explain\n"
        f"explain({str(sample_log)!r}, t={t_ns(45)})\n"
        "assert 'networkx' not in sys.modules, 'explain imported networkx'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)


def test_warm_summary_cycles_are_read_leniently(sample_log: Path) -> None:
    cycle = open_log(sample_log).cycle_at(t_ns(45))
    action = orjson.loads(cycle.payloads.pop(TOPIC_ACTION))
    cycle.summary = {
        TOPIC_ACTION: {
            "command": action["command"],
            "rationale": {"text": "summary", "factors": action["rationale"]["factors"]},
        }
    }
    d = read_decision(cycle)
    assert d.summary and d.command == "STOP" and d.rationale == "summary"
    assert [f.node for f in d.factors] == ["ped_1.distance", "collision_risk"]
    assert d.alternatives == () and d.tree is None


def test_find_cycle_uses_time_search(sample_log: Path) -> None:
    log = open_log(sample_log)
    assert [find_cycle(log, n).cycle for n in (0, 1, 50, 98, 99)] == [0, 1, 50, 98, 99]


# --- on a simulator log ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def sim_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from sim.runner import RunConfig, run

    out = tmp_path_factory.mktemp("sim") / "run.mcap"
    run(RunConfig(out=out, scenario="all", cycles=100, seed=42))
    return out


def test_sim_ped_close_stop_shows_the_papers_example(sim_log: Path) -> None:
    from trace_audit.transitions import timeline

    stops = [
        row
        for row in timeline(sim_log, every=True).rows
        if row.command == "STOP" and row.scenario == "ped_close"
    ]
    assert stops
    # The paper's cycle: the policy documents both ways out. Within the first second of the
    # stop (the episode's very first cycle may time out). Both ways out are SLOW now, not the
    # paper's CONTINUE for the risk: the worker stays within the 4 m slow zone (issue 16).
    candidates = [explain(sim_log, cycle=row.cycle) for row in stops[:10]]
    r = next(
        c
        for c in candidates
        if {(cf.factor.rsplit(".", 1)[-1], cf.would_select) for cf in c.decision.counterfactuals}
        >= {("distance", "SLOW"), ("collision_risk", "SLOW")}
    )
    d = r.decision
    assert d.command == "STOP"
    factors = {f.name: f for f in d.factors}
    distance, risk = factors["distance"], factors["collision_risk"]
    assert distance.unit == "m" and isinstance(distance.value, float)
    assert 1.0 <= distance.value <= 2.0  # a pedestrian at about 1.5 m
    assert isinstance(risk.value, float) and risk.value >= 0.2
    assert {a.command for a in d.alternatives} == {"SLOW", "REROUTE", "CONTINUE"}
    texts = [c.text for c in d.counterfactuals]
    assert any(t.startswith("would SLOW if distance >= ") for t in texts)
    assert any(t.startswith("would SLOW if collision_risk < ") for t in texts)
    # every factor's chain goes down to the LiDAR reading, each link marked either way
    g = _graph(r)
    for chain in r.chains.factors:
        assert [link.level for link in chain.links] == [
            "factor_node",
            "belief_path",
            "entity",
            "evidence_ref",
            "sensor_reading",
        ]
        mine = [(u, v) for u, v, f in g.edges(data="factors") if chain.node in f]
        assert len(mine) >= 5
    kinds = {data["kind"] for _, data in g.nodes(data=True)}
    assert kinds >= {"sensor", "evidence", "entity", "belief", "action"} or r.scores.et < 1


def test_sim_injected_null_evidence_shows_as_a_missing_link(sim_log: Path) -> None:
    from sim.faults import read_truth, truth_path_for

    nulls = [
        f
        for f in read_truth(truth_path_for(sim_log))
        if f["kind"] == "evidence_corruption" and f["detail"].get("mode") == "null"
    ]
    assert nulls, "the seeded run injects null evidence refs"
    fault = nulls[0]
    r = explain(sim_log, cycle=fault["cycle"])
    entity = fault["detail"]["entity"]
    hit = [
        c
        for c in r.chains.factors
        if any(link.level == "entity" and link.ref == entity for link in c.links)
    ]
    for chain in hit:
        assert not chain.traceable
        assert chain.missing is not None and chain.missing.level == "evidence_ref"
    g = _graph(r)
    assert (
        any(
            not data["documented"] and data["level"] == "evidence_ref"
            for _, _, data in g.edges(data=True)
        )
        or not hit
    )


def test_explain_scores_each_decision_as_the_metrics_do(sim_log: Path) -> None:
    """explain's per-decision ET / DR agree with what `trace-audit metrics` lists as failing."""
    from trace_audit.explanation import explain
    from trace_audit.metrics import MetricsConfig, compute_metrics

    report = compute_metrics([sim_log], MetricsConfig())
    failing = {f.cycle: f for f in report.failures}
    after_gap = {g.before_cycle for g in report.gaps}
    checked = 0
    for cycle in [c.cycle for c in open_log(sim_log).iter_cycles()]:
        scores = explain(sim_log, cycle=cycle).scores
        listed = failing.get(cycle)
        dr_listed = listed is not None and any(p.startswith("DR:") for p in listed.problems)
        assert (scores.dr == 0.0) == dr_listed, cycle
        if listed is not None:
            assert scores.et == pytest.approx(listed.et)
        else:
            assert scores.fully_traceable and scores.dr == 1.0
            # TCS is 1 unless the decision follows a gap (its continuity is then < 1).
            assert (scores.tcs < 1.0) == (cycle in after_gap), cycle
        checked += 1
    assert checked > 400 and failing  # the run has injected faults to disagree about


def test_a_counterfactual_tree_thousands_of_levels_deep_is_drawn_bounded(tmp_path: Path) -> None:
    """A log may hold any tree: one 5,000 levels deep must not exhaust the renderer's stack
    (it was a RecursionError traceback); the terminal shows the top, --json all of it."""
    depth = 5_000
    nodes = [TreeNode(id=f"n{i}", label=f"test {i}") for i in range(depth)]
    nodes.append(TreeNode(id="leaf", label="STOP", command="STOP"))
    edges = [TreeEdge(parent=f"n{i}", child=f"n{i + 1}", label="yes") for i in range(depth - 1)]
    edges.append(TreeEdge(parent=f"n{depth - 1}", child="leaf", label="yes"))
    path = tmp_path / "deep.mcap"
    logger = AuditLogger(path, robot_id="amr-1", config=LoggerConfig(threaded=False))
    p, b, a, e = synthetic_cycle(0)
    deep = a.model_copy(
        update={"tree": DecisionTree(nodes=nodes, edges=edges, taken_path=["n0", "leaf"])}
    )
    logger.log_cycle(1_000_000_000, perception=p, belief=b, action=deep, execution=e)
    logger.close()
    runner = CliRunner()
    for extra in (["--plain"], []):
        result = runner.invoke(app, ["explain", str(path), "--t", "1.0", *extra])
        assert result.exit_code == 0, result.output
        assert "deeper levels" in result.output
    result = runner.invoke(app, ["explain", str(path), "--t", "1.0", "--json"])
    assert result.exit_code == 0
    assert len(json.loads(result.stdout)["tree"]["nodes"]) == depth + 1


def test_a_catalogued_root_is_explained_alike_from_the_one_segment_it_needs(
    tmp_path: Path,
) -> None:
    """``explain`` opens a catalogued root lazily; its answer is the full log's, field for
    field, at every cycle (across segment boundaries, where the walk back reaches the
    previous segment) and between cycles."""
    root = write_log(tmp_path / "root", max_segment_s=3.0)
    refresh_catalog(root)
    full = open_log(root)
    assert len(full.segments) >= 3
    assert open_log(root, lazy=True)._all is None  # nothing opened: the catalog is trusted
    for index in range(0, 90, 7):
        for t in (t_ns(index), t_ns(index) + PERIOD_NS // 2):
            lazy = to_jsonable(explain(root, t=t))
            assert lazy == to_jsonable(explain(full, t=t))


# --- a robot restarted with its clock from zero -------------------------------------------------


@pytest.mark.parametrize("catalogued", [False, True], ids=["opened", "lazy"])
def test_a_restarted_clock_keeps_each_explanation_in_its_own_run(
    tmp_path: Path, catalogued: bool
) -> None:
    """Two runs of one robot in one root, both starting at T0 (a monotonic clock after a
    reboot): every cycle number is found, and the walk back (held since, previous seal)
    never steps into the other run's cycles at the same times."""
    root = write_log(tmp_path / "root")
    write_log(root)  # the same robot again: the chain goes on, the times start over
    if catalogued:
        refresh_catalog(root)
    first, second = sorted(p.name for p in (root / "hot").glob("*.mcap"))
    for number in (0, 45, 99, 100, 145, 199):
        r = explain(root, cycle=number)
        assert r.cycle == number
        assert r.clock_run == ((first,) if number < 100 else (second,))
        assert r.held.since_cycle <= number and r.held.since_cycle >= (0 if number < 100 else 100)
        assert r.seal.verified and r.seal.prev_ok
    by_time = explain(root, t=t_ns(45))
    assert by_time.decision.segment == second and by_time.held.since_cycle >= 100
    shown = CliRunner().invoke(app, ["explain", str(root), "--t", t_s(45), "--plain"]).output
    assert "the robot's clock went back in this log" in shown


def test_one_clock_run_is_the_whole_log(sample_log: Path) -> None:
    log = open_log(sample_log)
    assert log.clock_run(log.segments[0].path.name) is log
    assert explain(sample_log, t=t_ns(45)).clock_run == ()


def test_a_time_only_the_earlier_run_reached_is_answered_from_that_run(tmp_path: Path) -> None:
    """A robot killed at ~10 s and restarted with its clock from zero for 3 s: t = 9.5 s
    lies only in the first run; it must not be answered by the restarted run's last
    decision (with a made-up gap of 6.6 s)."""
    root = write_log(tmp_path / "root")  # t 100.0 .. 109.9 s
    write_log(root, DEFAULT_SCRIPT[:1])  # restarted: 100.0 .. 102.9 s, cycles 100..129
    late = explain(root, t=t_ns(95))
    assert (late.cycle, late.offset_ns, late.stale) == (95, 0, False)
    early = explain(root, t=t_ns(2))  # both runs hold 100.2 s: the later run answers
    assert early.cycle == 102 and early.clock_run


def test_the_cycle_in_flight_at_a_crash_is_unsealed_not_a_failed_seal(
    crashed_log: Path, tmp_path: Path
) -> None:
    """PROFILE §8: the layer messages after a crashed segment's last seal are the cycle the
    robot was writing when it was killed; its content cannot be verified, but nothing failed."""
    cut = cut_in_flight(crashed_log, tmp_path / "cut.mcap")
    r = explain(cut, t=t_ns(99))
    assert (r.cycle, r.seal.sealed, r.seal.in_flight, r.seal.verified) == (99, False, True, False)
    assert r.seal.problems == (
        "the robot stopped while writing this cycle: it was never sealed, so its content "
        "cannot be verified",
    )
    shown = CliRunner().invoke(app, ["explain", str(cut), "--t", t_s(99), "--plain"])
    assert shown.exit_code == 0, shown.output
    seal_line = next(line for line in shown.stdout.splitlines() if line.startswith("Seal"))
    assert "[UNSEALED]" in seal_line and "FAILED" not in shown.stdout
    assert "the robot stopped while writing this cycle" in shown.stdout
    # the cycle before it was sealed before the kill and verifies as usual
    assert explain(cut, t=t_ns(98)).seal.verified


def test_an_unsealed_last_cycle_of_a_closed_segment_still_fails(
    crashed_log: Path, tmp_path: Path
) -> None:
    """A segment the robot closed was not cut by a crash: a cycle without a seal there is
    a finding (inserted, or its seal removed), shown as a failed check."""
    closed = cut_in_flight(crashed_log, tmp_path / "closed.mcap", finished=True)
    r = explain(closed, t=t_ns(99))
    assert (r.seal.sealed, r.seal.in_flight, r.seal.verified) == (False, False, False)
    assert r.seal.problems == ("the cycle is not sealed",)
    shown = CliRunner().invoke(app, ["explain", str(closed), "--t", t_s(99), "--plain"])
    assert "[FAILED] not sealed" in shown.stdout and "UNSEALED" not in shown.stdout
