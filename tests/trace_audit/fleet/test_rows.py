"""The fleet index's rows keep list, struct and map columns flat; these pin what lands in
each column for decisions the simulator never logs (text factors, failed checks, integrity
problems, entities without ids or poses), so the flat layout cannot drift from the rows."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from tests.trace_audit.conftest import write_log
from trace_audit.fleet.rows import SegmentRows
from trace_audit.metrics import MetricsConfig, ScoredDecision, score_segment
from trace_runtime.reader import open_segment


def _scored(path: Path) -> list[ScoredDecision]:
    got: list[ScoredDecision] = []
    score_segment(path, None, MetricsConfig(max_listed=0), got.append)
    return got


def test_unusual_decisions_fill_every_column_as_rows_would(tmp_path: Path) -> None:
    log = write_log(tmp_path / "one.mcap")
    first, second, third = _scored(log)[:3]
    action = {
        "command": "STOP",
        "rationale": {
            "factors": [
                {"node": "n1", "name": "", "value": "high", "unit": "m"},
                "not a factor",
                {"node": "n2", "name": "gap", "value": True},
            ]
        },
        "alternatives": [{}, {}],
    }
    execution = {
        "flags": ["scenario:aisle", 3],
        "checks": [{"rule": "max_speed", "passed": False}, {"rule": "ok", "passed": True}],
        "deviation": 2,
    }
    belief = {
        "nodes": [{"id": "d", "kind": "state", "unit": "m", "label": "distance", "value": 1}],
        "edges": [{"parent": "p1", "child": "d"}],
    }
    perception = {"entities": [{"id": "p1", "class": "person"}, 7, {"class": "cart"}]}
    decisions = [
        dataclasses.replace(
            first, action=action, execution=execution, belief=belief, perception=perception
        ),
        dataclasses.replace(
            second,
            action=None,
            execution=None,
            perception=None,
            dr_problems=("no alternatives",),
            seal=second.seal._replace(problems=["chain link broken"]),
        ),
        third,
    ]
    rows = SegmentRows(open_segment(log), previous_command="SLOW")
    for decision in decisions:
        rows(decision)
    table, days = rows.table("decisions")
    unusual, damaged, plain = table.to_pylist()
    assert len(days) == 3
    assert unusual["factors"] == [
        {"node": "n1", "name": "", "value": None, "text": "high", "unit": "m"},
        {"node": "n2", "name": "gap", "value": 1.0, "text": None, "unit": None},
    ]
    assert (unusual["lead_factor"], unusual["lead_text"], unusual["lead_unit"]) == (
        "n1",
        "high",
        "m",
    )
    assert unusual["previous_command"] == "SLOW" and damaged["previous_command"] == "STOP"
    assert unusual["failed_checks"] == ["max_speed"]
    assert unusual["flags"] == ["scenario:aisle", "3"] and unusual["scenario"] == "aisle"
    assert unusual["nearest"] == [("person", 1.0)]
    assert (unusual["alternatives"], unusual["deviation"]) == (2, 2.0)
    assert damaged["factors"] == [] and damaged["flags"] == [] and damaged["nearest"] == []
    assert damaged["dr_problems"] == ["no alternatives"] and damaged["dr"] is False
    assert damaged["integrity_problems"] == ["chain link broken"]
    assert damaged["seal_verified"] is False and rows.integrity_failed == 1
    assert plain["factors"] == [
        {
            "node": f.get("node", ""),
            "name": f.get("name", ""),
            "value": float(f["value"]),
            "text": None,
            "unit": f.get("unit"),
        }
        for f in third.action["rationale"]["factors"]
    ]
    assert {table.column(name).null_count for name in ("segment", "tier", "factors")} == {0}
    entities = rows.table("entities")[0].to_pylist()
    assert [(e["entity"], e["class"], e["distance"]) for e in entities[:2]] == [
        ("p1", "person", 1.0),
        ("", "cart", None),
    ]
    assert {e["segment"] for e in entities} == {log.name}
