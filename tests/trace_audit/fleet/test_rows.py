"""The fleet index's rows keep list, struct and map columns flat; these pin what lands in
each column for decisions the simulator never logs (text factors, failed checks, integrity
problems, entities without ids or poses), so the flat layout cannot drift from the rows."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from tests.trace_audit.conftest import write_log
from trace_audit.fleet.rows import SegmentRows, day_of, partition_of
from trace_audit.metrics import MetricsConfig, ScoredDecision, score_segment
from trace_runtime.reading.reader import open_segment


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


def test_channels_and_checks_keep_what_is_logged_and_skip_what_is_not_a_record(
    tmp_path: Path,
) -> None:
    log = write_log(tmp_path / "one.mcap")
    first = _scored(log)[0]
    execution = {
        "deviation": 0.5,
        "deviation_unit": "m/s",
        "channels": [
            {"name": "grip", "unit": "N", "intended": 20, "actual": 18.5, "deviation": 1.5},
            "not a channel",
            {"name": "joint_1", "unit": "rad/s", "intended": 0.1},
        ],
        "checks": [
            {"rule": "max_grip", "passed": True, "value": 18.5, "limit": 40.0, "detail": ""},
            7,
            {"rule": "odd", "passed": "yes"},
        ],
    }
    rows = SegmentRows(open_segment(log), run="run-000003")
    rows(dataclasses.replace(first, execution=execution))
    channels, channel_days = rows.table("channels")
    assert [(c["channel"], c["intended"], c["actual"], c["deviation"], c["unit"])
            for c in channels.to_pylist()] == [
        ("grip", 20.0, 18.5, 1.5, "N"),
        ("joint_1", 0.1, None, None, "rad/s"),
    ]  # fmt: skip
    assert {c["deviation_unit"] for c in channels.to_pylist()} == {"m/s"}
    assert {c["segment"] for c in channels.to_pylist()} == {log.name}
    checks, check_days = rows.table("checks")
    assert [(c["rule"], c["passed"], c["value"], c["limit"]) for c in checks.to_pylist()] == [
        ("max_grip", True, 18.5, 40.0),
        ("odd", None, None, None),
    ]
    (decision,) = rows.table("decisions")[0].to_pylist()
    assert decision["deviation_unit"] == "m/s"
    # a sim clock's rows go under the run, whatever their time
    assert set(channel_days) == set(check_days) == set(rows.days["decisions"]) == {"run-000003"}


def test_the_partition_is_the_utc_day_only_on_a_wall_clock() -> None:
    wall_ns = 1_777_874_400 * 10**9  # 2026-05-04T06:00:00Z
    assert partition_of("system", wall_ns, 4) is None
    assert day_of(wall_ns) == "2026-05-04"
    assert partition_of("sim", wall_ns, 4) == "run-000004"
    assert partition_of("monotonic", 5 * 10**9, 0) == "run-000000"
    assert partition_of("system", 0, 12) == "run-000012"  # counting from 0: no time of day
