"""The pick-and-place arm example (issue 15): it runs by default in seconds, verifies, and
every investigator view shows its execution in the arm's own channel names and units."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from trace_audit.cli import app
from trace_audit.explanation import explain
from trace_audit.metrics import compute_metrics
from trace_audit.transitions import timeline
from trace_audit.verify import verify_log
from trace_runtime import open_log

ROOT = Path(__file__).resolve().parents[2]
V1_FIXTURE = ROOT / "tests" / "fixtures" / "v1" / "amr-fixture_000000.mcap"
CHANNELS = {
    "shoulder_pan": "rad/s",
    "shoulder_lift": "rad/s",
    "elbow": "rad/s",
    "wrist": "rad/s",
    "gripper_force": "N",
    "ee_speed": "m/s",
}


@pytest.fixture(scope="module")
def arm_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("arm") / "arm.mcap"
    script = ROOT / "examples" / "pick_and_place_arm.py"
    subprocess.run([sys.executable, str(script), "--out", str(out)], check=True, timeout=60)
    return out


def test_the_arm_runs_its_four_commands_and_verifies(arm_log: Path) -> None:
    cycles = list(open_log(arm_log).iter_cycles())
    assert len(cycles) == 240
    assert {c.action.command for c in cycles if c.action} == {"GRASP", "RETRY", "RELEASE", "HALT"}
    report = verify_log(arm_log)
    assert report.ok and report.cycles_valid == 240, report.findings


def test_explain_shows_the_arms_channels_in_their_units(arm_log: Path) -> None:
    result = CliRunner().invoke(app, ["explain", str(arm_log), "--t", "6.5", "--plain"])
    assert result.exit_code == 0, result.output
    text = result.stdout
    execution = text[text.index("Execution\n") :]
    for name, unit in CHANNELS.items():
        (row,) = [line for line in execution.splitlines() if line.strip().startswith(name)]
        assert row.rstrip().endswith(unit), row
    assert "rad/s\n" in execution and "Deviation" in execution and " m/s\n" in execution
    assert "? m/s" not in text and "? rad/s" not in text  # no planar motion was logged


def test_explain_json_carries_the_channels_and_a_v1_decision_does_not(arm_log: Path) -> None:
    result = explain(arm_log, t=6_500_000_000)
    ex = result.decision.execution
    assert ex is not None and not ex.planar and ex.deviation_unit == "m/s"
    assert {c.name: c.unit for c in ex.channels} == CHANNELS
    elbow = next(c for c in ex.channels if c.name == "elbow")
    assert elbow.deviation == pytest.approx(abs(elbow.actual - elbow.intended), abs=1e-4)  # type: ignore[operator]
    out = CliRunner().invoke(app, ["explain", str(V1_FIXTURE), "--cycle", "21", "--json"])
    v1 = json.loads(out.stdout)["decision"]["execution"]
    assert "channels" not in v1 and "deviation_unit" not in v1 and v1["intended"] == [0.5, -0.0]


def test_timeline_rows_give_the_largest_deviation_in_the_logged_unit(arm_log: Path) -> None:
    rows = timeline(arm_log).rows
    assert all(r.deviation_unit == "m/s" and r.max_deviation is not None for r in rows)
    assert max(r.max_deviation or 0.0 for r in rows) > 0.0
    assert all(r.max_deviation is None for r in timeline(V1_FIXTURE).rows)  # 1.0: no unit


def test_metrics_reports_deviation_per_channel_and_the_loggers_cost(arm_log: Path) -> None:
    report = compute_metrics([arm_log])
    got = {c.name: c for c in report.channel_deviation}
    assert {name: c.unit for name, c in got.items()} == CHANNELS
    assert all(c.cycles == c.logged == 240 for c in got.values())
    # the gripper's slip: commanded 20 N, held 6 N for a cycle
    assert got["gripper_force"].max == pytest.approx(14.0)
    cost = report.logging_cost
    assert cost is not None and cost.cycles == 30 and cost.p50_ns is not None  # 1 in 8 timed
    assert cost.p99_ns is not None and 0 < cost.p50_ns <= cost.p99_ns <= (cost.max_ns or 0)
    assert ", p50 " in report.logging_time and report.logging_time != "not logged"
    plain = CliRunner().invoke(app, ["metrics", str(arm_log), "--plain"]).stdout
    assert "Execution deviation per channel" in plain and "gripper_force" in plain
    assert compute_metrics([V1_FIXTURE]).channel_deviation == ()


def test_the_incident_report_draws_the_arms_channels_in_their_units(arm_log: Path) -> None:
    from trace_audit.incident import build_report

    report = build_report(arm_log, t="6.5")
    samples = report.data.samples
    assert samples, "the report gathered no cycles of the window"
    drawn = set().union(*(s.channels for s in samples))
    assert {f"{name} ({unit})" for name, unit in CHANNELS.items()} <= drawn
    assert "linear speed (m/s)" not in drawn  # the arm logged no planar motion
    for name, unit in CHANNELS.items():
        assert f"{name} ({unit})" in report.html
