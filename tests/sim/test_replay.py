"""``trace-sim check-counterfactuals``: the replay finds a counterfactual the policy does not
back, and passes the ones the prober found."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

import sim.decision
from sim import FaultRates, RunConfig, run
from sim.cli import app
from sim.counterfactual import Found
from sim.replay import check_counterfactuals


def _run(out: Path) -> Path:
    run(RunConfig(out=out, scenario="ped_close", cycles=40, seed=2, faults=FaultRates.off()))
    return out


def test_a_run_replays_cleanly_and_the_cli_exits_0(tmp_path: Path) -> None:
    log = _run(tmp_path / "ok.mcap")
    report = check_counterfactuals(log)
    assert report.ok and report.decisions == 40 and report.counterfactuals > 40
    result = CliRunner().invoke(app, ["check-counterfactuals", str(log), "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.output)["ok"] is True


def test_a_false_counterfactual_in_the_log_is_listed_and_exits_1(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A prober that shifts every threshold by 0.5 writes claims the policy does not back."""
    real = sim.decision.probe

    def shifted(*args: object, **kwargs: object) -> list[Found]:
        found = real(*args, **kwargs)  # type: ignore[arg-type]
        return [
            Found(f.factor, f.comparison, round(f.threshold + 0.5, 2), f.would_select)
            for f in found
        ]

    monkeypatch.setattr(sim.decision, "probe", shifted)
    log = _run(tmp_path / "bad.mcap")
    report = check_counterfactuals(log)
    assert not report.ok
    assert {f.what for f in report.findings} == {"counterfactual"}
    result = CliRunner().invoke(app, ["check-counterfactuals", str(log), "--plain"])
    assert result.exit_code == 1
    assert "does not hold" in result.output


def test_an_unreadable_log_exits_3_with_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "not.mcap"
    bad.write_bytes(b"not an mcap file")
    result = CliRunner().invoke(app, ["check-counterfactuals", str(bad)])
    assert result.exit_code == 3
    assert result.output.count("\n") == 1 and "trace-sim: cannot read" in result.output


def test_a_log_another_robot_wrote_is_refused_in_one_line_exit_2(tmp_path: Path) -> None:
    """The replay can only re-run the simulator's own policy: another robot's log (here the
    pick-and-place arm example) is a usage error, not a finding and not a traceback."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[2]
    out = tmp_path / "other.mcap"
    subprocess.run(
        [sys.executable, str(root / "examples" / "pick_and_place_arm.py"), "--out", str(out)],
        check=True,
        capture_output=True,
        timeout=120,
    )
    result = CliRunner().invoke(app, ["check-counterfactuals", str(out)])
    assert result.exit_code == 2, result.output
    [line] = result.stderr.strip().splitlines()
    assert "re-runs only the simulator's policy" in line
