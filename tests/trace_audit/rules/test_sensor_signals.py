"""Sensor health as rule signals: ``perception.sensors_unavailable[.<sensor>]``,
``perception.sensors_used[.<sensor>]`` and ``evidence.age_s[.<sensor>]``, on a robot that
cites a rosbag2 recording (``tests/trace_audit/ros2_bag.py``): its wrist camera is
unavailable throughout, and its scan is stuck from cycle ``STALE_FROM`` on."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.trace_audit.ros2_bag import CYCLES, PERIOD_NS, STALE_FROM, Robot, write_robot
from tests.trace_audit.rules.check_helpers import rule_text, rules_file
from trace_audit.cli import app
from trace_audit.rules import Outcome, RuleResult, RulesError, check_rules, parse_rules
from trace_audit.rules.index_check import check_index


@pytest.fixture(scope="module")
def robot(tmp_path_factory: pytest.TempPathFactory) -> Robot:
    return write_robot(tmp_path_factory.mktemp("ward"))


def _judged(log: Path, stl: str) -> RuleResult:
    (rule,) = check_rules(log, parse_rules(rule_text("r", stl))).robots[0].rules
    return rule


def test_a_stale_reading_violates_an_age_limit_exactly_where_it_is_stale(robot: Robot) -> None:
    limit = 0.075  # 1.5 periods at 20 Hz
    rule = _judged(robot.log, f"always(evidence.age_s.lidar <= {limit})")
    assert rule.outcome is Outcome.VIOLATED
    [violation] = rule.violations
    # the scan stuck at cycle STALE_FROM, 10 ms before it: 60 ms old one cycle later, 110 two
    assert (violation.first_cycle, violation.last_cycle) == (STALE_FROM + 2, CYCLES - 1)
    oldest_s = ((CYCLES - 1 - STALE_FROM) * PERIOD_NS + 10_000_000) / 1e9
    assert violation.robustness == pytest.approx(limit - oldest_s)
    # the camera and the joint states stay fresh; the oldest of all is the scan
    assert _judged(robot.log, "always(evidence.age_s.head_camera <= 0.02)").outcome is (
        Outcome.SATISFIED
    )
    whole = _judged(robot.log, f"always(evidence.age_s <= {limit})")
    assert [(v.first_cycle, v.last_cycle) for v in whole.violations] == [
        (STALE_FROM + 2, CYCLES - 1)
    ]


def test_sensors_the_robot_said_it_missed_are_counted_and_named(robot: Robot) -> None:
    named = _judged(robot.log, "always(perception.sensors_unavailable.wrist_camera < 0.5)")
    assert named.outcome is Outcome.VIOLATED
    assert [(v.first_cycle, v.last_cycle) for v in named.violations] == [(0, CYCLES - 1)]
    counted = _judged(robot.log, "always(perception.sensors_unavailable <= 1)")
    assert counted.outcome is Outcome.SATISFIED and counted.robustness == 0.0
    used = _judged(robot.log, "always(perception.sensors_used.lidar > 0.5)")
    assert used.outcome is Outcome.SATISFIED
    never = _judged(robot.log, "always(perception.sensors_unavailable.lidar < 0.5)")
    assert never.outcome is Outcome.SATISFIED
    assert never.unseen == ("perception.sensors_unavailable.lidar",)


@pytest.mark.parametrize(
    ("stl", "said"),
    [
        ("always(perception.sensors_lost > 0)", "perception.sensors_unavailable|sensors_used"),
        ("always(evidence.age > 0)", "evidence.age_s[.<sensor>]"),
    ],
)
def test_a_misspelt_sensor_signal_is_refused_when_the_rules_are_read(stl: str, said: str) -> None:
    with pytest.raises(RulesError, match="rule 'r'") as err:
        parse_rules(rule_text("r", stl))
    assert said in str(err.value)


def test_the_fleet_index_refuses_signals_it_does_not_hold() -> None:
    """The index has no sensor lists or ages: a rule that reads them is refused before a
    row is read, never judged "not decidable" everywhere."""

    def query(sql: str, params: object) -> dict[str, object]:
        raise AssertionError("the index must not be read")

    rules = parse_rules(rule_text("fresh", "always(evidence.age_s <= 0.1)"))
    with pytest.raises(RulesError, match="read from the logs, not the fleet index"):
        check_index(query, rules, rules_file="r.toml")  # type: ignore[arg-type]


def test_check_cli_exits_1_and_names_the_stale_cycles(robot: Robot, tmp_path: Path) -> None:
    path = rules_file(tmp_path, rule_text("fresh_scan", "always(evidence.age_s.lidar <= 0.075)"))
    shown = CliRunner().invoke(app, ["check", str(robot.log), "--rules", path, "--json"])
    assert shown.exit_code == 1, shown.output
    [answer] = json.loads(shown.stdout)["robots"]
    [rule] = answer["rules"]
    assert rule["outcome"] == "violated"
    assert [(v["first_cycle"], v["last_cycle"]) for v in rule["violations"]] == [
        (STALE_FROM + 2, CYCLES - 1)
    ]
