"""Metrics against the simulator's ground truth: they find exactly the injected faults.

The metrics read only the log. These tests read the simulator's truth sidecar (which the
library never does) and derive, fault by fault, which decisions must come out not fully
traceable or not reconstructable and which cycles must fall in gaps; the metrics must
flag exactly those (precision and recall 1.0), and with injection off every metric is 100%.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from sim import FaultRates, RunConfig, RunResult, read_truth, run
from sim.records import Edge, entities_under
from trace_audit.metrics import MetricsConfig, MetricsReport, compute_metrics
from trace_runtime import open_log

HEAVY = FaultRates(
    lidar_unavailable=0.05,
    camera_unavailable=0.15,
    evidence_corruption=0.08,
    edge_write_failure=0.08,
    rationale_truncation=0.06,
    counterfactual_timeout=0.06,
    audit_write_timeout=0.04,
)


@pytest.fixture(scope="module")
def heavy(tmp_path_factory: pytest.TempPathFactory) -> RunResult:
    out = tmp_path_factory.mktemp("heavy") / "run.mcap"
    return run(RunConfig(out=out, total_cycles=1500, seed=21, faults=HEAVY))


@pytest.fixture(scope="module")
def paper(tmp_path_factory: pytest.TempPathFactory) -> RunResult:
    out = tmp_path_factory.mktemp("paper") / "run.mcap"
    return run(RunConfig(out=out, scenario="all", cycles=100, seed=42))


@pytest.fixture(scope="module")
def clean(tmp_path_factory: pytest.TempPathFactory) -> RunResult:
    out = tmp_path_factory.mktemp("clean")  # a log root
    return run(RunConfig(out=out, scenario="all", cycles=100, seed=7, faults=FaultRates.off()))


def _expected(result: RunResult) -> tuple[set[int], set[int], set[int]]:
    """(not fully traceable, not reconstructable, lost cycles) from the truth sidecar.

    The faults come from the truth; only the logged belief graph's shape (which entities a
    factor's edges reach) is read from the log, through the simulator's own helper.
    """
    truth = read_truth(result.truth)
    by_cycle: dict[int, list[dict[str, Any]]] = {}
    for line in truth:
        by_cycle.setdefault(line["cycle"], []).append(line)
    lost = {t["cycle"] for t in truth if t["detail"].get("dropped")}
    untraceable: set[int] = set()
    unreconstructable: set[int] = set()
    for cycle in open_log(result.out).iter_cycles():
        faults = by_cycle.get(cycle.cycle, [])
        kinds = {f["kind"] for f in faults}
        if kinds & {"rationale_truncation", "counterfactual_timeout"}:
            unreconstructable.add(cycle.cycle)
        action = cycle.json("/trace/action")
        factors = [f["node"] for f in action["rationale"]["factors"]]
        if not factors:  # the truncation lost every factor: nothing left to trace
            untraceable.add(cycle.cycle)
            continue
        belief = cycle.json("/trace/belief")
        entity_of = {n["id"]: n["entity"] for n in belief["nodes"] if n["kind"] == "entity"}
        edges = [Edge(e["parent"], e["child"], e["p"], e["rule"]) for e in belief["edges"]]
        corrupted = {f["detail"]["entity"] for f in faults if f["kind"] == "evidence_corruption"}
        broken = {
            b
            for f in faults
            if f["kind"] == "edge_write_failure"
            for b in f["detail"]["broken_factors"]
        }
        for factor in factors:
            if factor in broken:
                untraceable.add(cycle.cycle)
                continue
            if factor in entity_of:
                reached = {entity_of[factor]}
            else:
                reached = {entity_of[n] for n in entities_under(factor, edges, set(entity_of))}
            if reached <= corrupted:
                untraceable.add(cycle.cycle)
    return untraceable, unreconstructable, lost


def _found(report: MetricsReport) -> tuple[set[int], set[int], set[int]]:
    untraceable = {f.cycle for f in report.failures if any(p.startswith("ET:") for p in f.problems)}
    unreconstructable = {
        f.cycle for f in report.failures if any(p.startswith("DR:") for p in f.problems)
    }
    in_gaps = {c for g in report.gaps for c in range(g.after_cycle + 1, g.before_cycle)}
    return untraceable, unreconstructable, in_gaps


def _precision_recall(found: set[int], expected: set[int]) -> tuple[float, float]:
    hit = len(found & expected)
    return (hit / len(found) if found else 1.0, hit / len(expected) if expected else 1.0)


@pytest.mark.parametrize("which", ["heavy", "paper"])
def test_metrics_find_exactly_the_injected_faults(
    which: str, request: pytest.FixtureRequest
) -> None:
    result: RunResult = request.getfixturevalue(which)
    report = compute_metrics([result.out], MetricsConfig(max_listed=100_000))
    untraceable, unreconstructable, lost = _expected(result)
    found_u, found_r, found_gaps = _found(report)
    last = max(c.cycle for c in open_log(result.out).iter_cycles())
    visible_lost = {c for c in lost if c < last}  # a drop after the last seal leaves no gap

    assert untraceable, "the run should contain traceability faults"
    assert _precision_recall(found_u, untraceable) == (1.0, 1.0), (
        sorted(found_u - untraceable),
        sorted(untraceable - found_u),
    )
    assert _precision_recall(found_r, unreconstructable) == (1.0, 1.0), (
        sorted(found_r - unreconstructable),
        sorted(unreconstructable - found_r),
    )
    assert found_gaps == visible_lost
    o = report.overall
    assert o.decisions == result.written
    assert o.decisions - o.fully_traceable == len(untraceable)
    assert o.not_reconstructable == len(unreconstructable)
    assert o.declared_dropped == o.missing_cycles == len(visible_lost)
    assert o.integrity_failed == 0
    assert o.tc == pytest.approx(1 - len(visible_lost) * 0.1 / o.window_s)


def test_without_injection_every_metric_is_100_percent(clean: RunResult) -> None:
    report = compute_metrics([clean.out], MetricsConfig(by="scenario", max_listed=100))
    o = report.overall
    assert o.decisions == 500
    assert (o.et.mean, o.fully_traceable_share.mean, o.et_partial.mean) == (1.0, 1.0, 1.0)
    assert (o.tc, o.dr, o.tcs.mean) == (1.0, 1.0, 1.0)
    assert (o.gaps, o.declared_dropped, o.integrity_failed, report.failures_total) == (0, 0, 0, 0)
    assert [g.name for g in report.groups] == [
        "clear_path",
        "ped_crossing",
        "ped_close",
        "multi_ped",
        "forklift",
    ]
    assert all(g.decisions == 100 for g in report.groups)


def test_scenario_groups_partition_the_decisions_and_window(paper: RunResult) -> None:
    report = compute_metrics([paper.out], MetricsConfig(by="scenario"))
    assert sum(g.decisions for g in report.groups) == report.overall.decisions
    assert sum(g.window_s for g in report.groups) == pytest.approx(report.overall.window_s)
    assert sum(g.fully_traceable for g in report.groups) == report.overall.fully_traceable
    assert report.across_groups is not None and report.across_groups.groups == 5


def test_cli_on_a_500_cycle_sim_log_gives_tables_and_json(paper: RunResult) -> None:
    import json

    from typer.testing import CliRunner

    from trace_audit.cli import app

    result = CliRunner().invoke(app, ["metrics", str(paper.out), "--by", "scenario", "--json"])
    assert result.exit_code == 0
    data = json.loads(result.stdout)
    assert data["table_ii"]["decisions"] == paper.written
    assert len(data["table_iii"]) == 5
    plain = CliRunner().invoke(app, ["metrics", str(paper.out), "--by", "scenario", "--plain"])
    assert plain.exit_code == 0 and "Per scenario" in plain.stdout


def test_sim_root_and_file_agree(tmp_path: Path) -> None:
    rates = FaultRates(evidence_corruption=0.1, audit_write_timeout=0.05)
    a = run(RunConfig(out=tmp_path / "a.mcap", total_cycles=300, seed=4, faults=rates))
    b = run(RunConfig(out=tmp_path / "root", total_cycles=300, seed=4, faults=rates))
    ra = compute_metrics([a.out], MetricsConfig(max_listed=1000))
    rb = compute_metrics([b.out], MetricsConfig(max_listed=1000, workers=2))
    assert ra.overall.decisions == rb.overall.decisions
    assert ra.overall.et == rb.overall.et and ra.overall.tc == rb.overall.tc
    assert [f.cycle for f in ra.failures] == [f.cycle for f in rb.failures]


def test_metrics_across_tiers(tmp_path: Path) -> None:
    """Cold is lossless: the same metrics. Warm summaries keep DR and TC, lose readings."""
    from trace_runtime.tiers import WarmPolicy, compact

    rates = FaultRates(
        evidence_corruption=0.05, rationale_truncation=0.05, audit_write_timeout=0.03
    )
    roots = {}
    for tier in ("hot", "cold", "warm"):
        roots[tier] = tmp_path / tier
        run(RunConfig(out=roots[tier], total_cycles=400, seed=8, faults=rates))
    compact(roots["cold"], "cold", older_than_ns=0, sources=["hot"], retention_ns=None)
    compact(
        roots["warm"], "warm", older_than_ns=0, warm=WarmPolicy(context_ns=0), retention_ns=None
    )
    assert not list((roots["cold"] / "hot").glob("*.mcap"))
    assert not list((roots["warm"] / "hot").glob("*.mcap"))
    config = MetricsConfig(by="scenario", max_listed=10_000)
    hot, cold, warm = (compute_metrics([roots[t]], config) for t in ("hot", "cold", "warm"))
    assert _tables(cold) == _tables(hot)
    assert [f.problems for f in cold.failures] == [f.problems for f in hot.failures]

    w, h = warm.overall, hot.overall
    summaries = {c.cycle for c in open_log(roots["warm"]).iter_cycles() if c.is_summary}
    assert w.decisions == h.decisions and w.summarized == len(summaries) > 100
    assert (w.tc, w.gaps, w.declared_dropped) == (h.tc, h.gaps, h.declared_dropped)
    assert (w.dr, w.not_reconstructable) == (h.dr, h.not_reconstructable)
    assert w.integrity_failed == 0
    hot_bad, warm_bad = _untraceable(hot), _untraceable(warm)
    # Summaries keep every ref but drop the readings, so chains only lose their last link:
    # on summary cycles, and on full cycles that cite a reading logged in a summary cycle.
    assert hot_bad <= warm_bad
    assert len((warm_bad - hot_bad) & summaries) > 100
    for failure in warm.failures:
        if failure.cycle in warm_bad - hot_bad:
            et = [p for p in failure.problems if p.startswith("ET:")]
            assert all("sensor_reading missing" in p for p in et), failure
    assert w.et_partial.mean < h.et_partial.mean


def _untraceable(report: MetricsReport) -> set[int]:
    return {f.cycle for f in report.failures if any(p.startswith("ET:") for p in f.problems)}


def _tables(report: MetricsReport) -> tuple[object, ...]:
    return (report.overall, report.groups, report.gaps)
