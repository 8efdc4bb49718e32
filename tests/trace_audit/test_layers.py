"""Whole layers as Arrow tables (``trace_audit.layers``): each table holds what the records
hold, read here independently from the raw cycles; robots and windows select as every command
does; nothing assumes a planar robot."""

from __future__ import annotations

import hashlib
import shutil
import sys
from pathlib import Path
from typing import Any

import orjson
import pytest

from tests.trace_audit.conftest import PERIOD_NS, T0_NS, rewrite_segment, t_ns, write_log
from trace_audit import (
    channel_table,
    check_table,
    decision_table,
    entity_table,
    gap_table,
    iter_decisions,
    read_decision,
)
from trace_runtime import AuditLogger, LoggerConfig, RawMessage, open_log
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.errors import UsageError
from trace_runtime.records import TOPIC_ACTION, TOPIC_EXECUTION, TOPIC_PERCEPTION, TOPIC_SEAL

pytest.importorskip("pyarrow")

AMR, ARM = "amr-7", "arm-2"
ARM_CYCLES = 20
SKIPPED = (40, 41, 42)


@pytest.fixture(scope="module")
def root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two robots in one root: a mobile base with a gap of three dropped cycles, and an arm
    logging actuator channels whose entities carry no position."""
    where = tmp_path_factory.mktemp("layers") / "root"
    write_log(where, robot_id=AMR, skip=lambda i: i in SKIPPED)
    _write_arm(where)
    segment = where / "hot" / f"{ARM}_000000.mcap"
    original = segment.with_suffix(".orig")
    shutil.move(segment, original)
    rewrite_segment(original, segment, _without_poses)
    original.unlink()
    return where


def _write_arm(root: Path) -> None:
    config = LoggerConfig(threaded=False, fsync_interval_s=None)
    with AuditLogger(root, robot_id=ARM, period_s=PERIOD_NS / 1e9, config=config) as log:
        for i in range(ARM_CYCLES):
            with log.cycle(t_ns(i)) as c:
                ref = c.sensor("/sensors/camera", {"hand_m": 0.3 + i / 100})
                c.perception(
                    {
                        "entities": [
                            {
                                "id": "hand",
                                "class": "hand",
                                "pose": {"position": [0.3, 0.1, 0.2]},
                                "confidence": {"hand": 0.8},
                                "evidence": [
                                    {"sensor": "camera", "weight": 1.0, "ref": ref.model_dump()}
                                ],
                            }
                        ]
                    }
                )
                c.belief({"nodes": [{"id": "near", "kind": "state", "label": "near", "p": 0.9}]})
                c.action(
                    {
                        "command": "HALT" if i % 5 == 0 else "GRASP",
                        "score": 0.7,
                        "rationale": {
                            "text": "hand near",
                            "factors": [{"node": "near", "value": True}],
                        },
                    }
                )
                grip = 10.0 + i
                c.execution(
                    {
                        "deviation": 0.01 * i,
                        "deviation_unit": "m/s",
                        "channels": [
                            {"name": "elbow", "unit": "rad/s", "intended": 0.5, "actual": 0.4},
                            {
                                "name": "grip",
                                "unit": "N",
                                "intended": 12.0,
                                "actual": grip,
                                "deviation": abs(grip - 12.0),
                            },
                        ],
                        "checks": [
                            {"rule": "max_grip", "passed": grip <= 20.0, "value": grip, "limit": 20}
                        ],
                    }
                )


def _without_poses(msg: RawMessage) -> bytes:
    """The arm's perception as another writer might log it: entities without a pose."""
    if msg.topic != TOPIC_PERCEPTION:
        return msg.data
    record = orjson.loads(msg.data)
    for entity in record["entities"]:
        del entity["pose"]
    return orjson.dumps(record)


def _raw_cycles(root: Path, robot: str) -> list[Cycle]:
    return list(open_log(root).iter_cycles(robot=robot))


def _layer(cycle: Cycle, topic: str) -> Any:
    data = cycle.payloads.get(topic)
    return None if data is None else orjson.loads(data)


def _matches_seal(cycle: Cycle) -> bool:
    seal = _layer(cycle, TOPIC_SEAL)
    named = seal["digests"]
    return set(named) == set(cycle.payloads) - {TOPIC_SEAL} and all(
        hashlib.sha256(cycle.payloads[t]).hexdigest() == d for t, d in named.items()
    )


def _rows(table: Any, *columns: str) -> list[tuple[Any, ...]]:
    data = table.to_pydict()
    return list(zip(*(data[c] for c in columns), strict=True))


def test_decisions_hold_what_each_robots_records_hold(root: Path) -> None:
    table = decision_table(root)
    expected = []
    for robot in (AMR, ARM):  # robots in order of name
        for cycle in _raw_cycles(root, robot):
            action, execution = _layer(cycle, TOPIC_ACTION), _layer(cycle, TOPIC_EXECUTION)
            factors = action["rationale"].get("factors", [])
            expected.append(
                (
                    robot,
                    cycle.cycle,
                    cycle.t_ns,
                    action["command"],
                    action["score"],
                    action["rationale"]["text"],
                    factors[0].get("name") or factors[0]["node"],
                    len(factors),
                    execution["deviation"],
                    execution.get("deviation_unit"),
                    [c["rule"] for c in execution.get("checks", []) if not c["passed"]],
                    execution.get("flags", []),
                    TOPIC_SEAL in cycle.payloads,
                    _matches_seal(cycle),
                )
            )
    got = _rows(
        table,
        "robot",
        "cycle",
        "t_ns",
        "command",
        "score",
        "rationale",
        "lead_factor",
        "factors",
        "deviation",
        "deviation_unit",
        "failed_checks",
        "flags",
        "sealed",
        "seal_verified",
    )
    got = [(*row[:7], len(row[7]), *row[8:]) for row in got]
    assert got == expected
    assert len(got) == 100 - len(SKIPPED) + ARM_CYCLES
    # the arm's perception was rewritten after sealing: its decisions do not verify
    verified = {(r, v) for r, v in _rows(table, "robot", "seal_verified")}
    assert verified == {(AMR, True), (ARM, False)}


def test_the_leading_factor_keeps_its_value_and_unit(root: Path) -> None:
    table = decision_table(root, robots=AMR, start=t_ns(45), end=t_ns(45))
    (row,) = table.to_pylist()
    # cycle 45 is in the first ped_close stretch: distance 1.5 m leads
    assert (row["lead_factor"], row["lead_value"], row["lead_unit"]) == ("distance", 1.5, "m")
    assert row["lead_text"] is None and row["scenario"] == "ped_close"
    assert row["factors"][0] == {
        "node": "ped_1.distance",
        "name": "distance",
        "value": 1.5,
        "text": None,
        "unit": "m",
    }


def test_a_robot_selection_returns_exactly_that_robots_rows(root: Path) -> None:
    for robot, cycles in ((AMR, 100 - len(SKIPPED)), (ARM, ARM_CYCLES)):
        for robots in (robot, [robot]):
            table = decision_table(root, robots=robots)
            assert set(table.column("robot").to_pylist()) == {robot}
            assert table.num_rows == cycles
            assert table.column("cycle").to_pylist() == [c.cycle for c in _raw_cycles(root, robot)]
        assert set(entity_table(root, robots=[robot]).column("robot").to_pylist()) == {robot}
    assert check_table(root, robots=[ARM]).num_rows == ARM_CYCLES
    with pytest.raises(UsageError, match="holds amr-7, arm-2"):
        decision_table(root, robots=["nobody"])


def test_a_window_keeps_the_cycles_inside_it_in_the_logs_clock(root: Path) -> None:
    table = decision_table(root, robots=[AMR], start=t_ns(10), end=t_ns(19))
    assert table.column("cycle").to_pylist() == list(range(10, 20))
    as_text = decision_table(root, robots=[AMR], start="101", end="101.9")
    assert as_text.equals(table)
    relative = decision_table(root, start="+1", end="+1.9")  # both robots start at 100 s
    assert _rows(relative, "robot", "cycle") == [(r, c) for r in (AMR, ARM) for c in range(10, 20)]
    assert decision_table(root, start=t_ns(200)).num_rows == 0


def test_entities_give_positions_where_logged_and_nulls_where_not(root: Path) -> None:
    table = entity_table(root)
    expected = []
    for robot in (AMR, ARM):
        for cycle in _raw_cycles(root, robot):
            for entity in _layer(cycle, TOPIC_PERCEPTION)["entities"]:
                position = entity.get("pose", {}).get("position", [None, None, None])
                expected.append(
                    (
                        robot,
                        cycle.cycle,
                        cycle.t_ns,
                        entity["id"],
                        entity["class"],
                        entity["confidence"][entity["class"]],
                        *position,
                        len(entity["evidence"]),
                    )
                )
    columns = ("robot", "cycle", "t_ns", "entity", "class", "confidence", "x", "y", "z")
    assert _rows(table, *columns, "evidence") == expected
    arm = entity_table(root, robots=[ARM]).to_pylist()
    assert len(arm) == ARM_CYCLES
    assert all(r["x"] is None and r["y"] is None and r["z"] is None for r in arm)
    assert all(r["frame"] is None for r in arm)
    amr = entity_table(root, robots=[AMR]).to_pylist()
    assert all(r["x"] is not None and r["z"] == 0.0 and r["frame"] == "map" for r in amr)


def test_channels_keep_each_channels_unit_and_the_records_deviation_unit(root: Path) -> None:
    table = channel_table(root)
    expected = [
        (
            ARM,
            cycle.cycle,
            channel["name"],
            channel.get("intended"),
            channel.get("actual"),
            channel.get("deviation"),
            channel["unit"],
            "m/s",
        )
        for cycle in _raw_cycles(root, ARM)
        for channel in _layer(cycle, TOPIC_EXECUTION)["channels"]
    ]
    columns = ("robot", "cycle", "channel", "intended", "actual", "deviation", "unit")
    assert _rows(table, *columns, "deviation_unit") == expected
    assert channel_table(root, robots=[AMR]).num_rows == 0  # a planar base logs no channels


def test_checks_hold_every_rule_outcome(root: Path) -> None:
    table = check_table(root)
    expected = [
        (robot, cycle.cycle, cycle.t_ns, c["rule"], c["passed"], c.get("value"), c.get("limit"))
        for robot in (AMR, ARM)
        for cycle in _raw_cycles(root, robot)
        for c in _layer(cycle, TOPIC_EXECUTION)["checks"]
    ]
    columns = ("robot", "cycle", "t_ns", "rule", "passed", "value", "limit")
    assert _rows(table, *columns) == expected
    failed = [r for r in table.to_pylist() if not r["passed"]]
    assert [r["cycle"] for r in failed] == list(range(11, ARM_CYCLES))  # grip > 20 N


def test_gaps_are_the_dropped_cycles_between_seals(root: Path) -> None:
    table = gap_table(root)
    assert table.to_pylist() == [
        {
            "robot": AMR,
            "after_cycle": 39,
            "after_t_ns": t_ns(39),
            "before_cycle": 43,
            "before_t_ns": t_ns(43),
            "period_ns": PERIOD_NS,
            "gap_ns": 3 * PERIOD_NS,
            "missing_cycles": 3,
            "declared_dropped": 3,
        }
    ]
    assert gap_table(root, robots=[ARM]).num_rows == 0
    assert gap_table(root, end=t_ns(39)).num_rows == 0  # the gap ends outside the window


def test_iter_decisions_yields_the_decisions_the_cli_reads(root: Path) -> None:
    got = list(iter_decisions(root, start=t_ns(5), end=t_ns(7)))
    expected = [
        (robot, read_decision(cycle))
        for robot in (AMR, ARM)
        for cycle in open_log(root).iter_cycles(t_ns(5), t_ns(7), robot=robot)
    ]
    assert [(d.robot, d.decision) for d in got] == expected
    assert got[0].decision.cycle == 5 and got[0].decision.t_ns == T0_NS + 5 * PERIOD_NS


def test_the_tables_name_the_extra_when_pyarrow_is_missing(
    root: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "pyarrow", None)
    with pytest.raises(UsageError, match=r"pip install 'trace-audit\[fleet\]'"):
        decision_table(root)
    assert next(iter_decisions(root)).robot == AMR  # the typed decisions need no pyarrow


def test_an_unknown_robot_is_refused_before_anything_is_read(root: Path) -> None:
    with pytest.raises(UsageError, match="robot 'nobody' is not in this log"):
        iter_decisions(root, robots="nobody")
