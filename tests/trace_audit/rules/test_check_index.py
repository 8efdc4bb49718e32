"""check --index: the rules judged over a fleet index equal check on the logs, cycle for cycle."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from tests.trace_audit.conftest import stretch, write_log
from trace_audit.cli import app
from trace_audit.rules.index_check import NOT_WALL_CLOCK

ROOT = Path(__file__).resolve().parents[3]
WAREHOUSE = ROOT / "docs" / "rules" / "warehouse.toml"

# Every signal family the index holds, with violations, missing signals and horizons.
EXTRA = """
[[rule]]
name = "never_stop"
stl = "always(command.STOP < 0.5)"

[[rule]]
name = "keep_3m"
stl = "always(nearest.person >= 3.0)"

[[rule]]
name = "stop_response_passes"
stl = "always(check.stop_response > 0.5)"

[[rule]]
name = "degraded_clears"
stl = "always(eventually[0:0.5](flag.sensor_degraded < 0.5))"

[[rule]]
name = "low_risk"
stl = "always(historically[0:0.2](factor.collision_risk < 0.6))"
"""


def _run(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(app, list(args))
    return result.exit_code, result.stdout, result.stderr


def _sim(out: Path, robot: str, seed: int, *extra: str) -> None:
    subprocess.run(
        [
            *(sys.executable, "-m", "evaluation.cli", "run", "--duration", "1m"),
            *("--seed", str(seed), "--robot-id", robot, "--out", str(out), *extra),
        ],
        check=True,
        capture_output=True,
        cwd=ROOT,
    )


def _index(logs: Path, out: Path) -> Path:
    code, _, err = _run("index", str(logs), "--out", str(out))
    assert code == 0, err
    return out


def _rules_file(tmp_path: Path) -> Path:
    path = tmp_path / "rules.toml"
    path.write_text(WAREHOUSE.read_text() + EXTRA)
    return path


def _check(*args: str) -> tuple[int, dict[str, Any]]:
    code, out, err = _run("check", *args, "--json")
    assert code in (0, 1), err
    return code, json.loads(out)


def _without_explain(rule: dict[str, Any]) -> dict[str, Any]:
    out = dict(rule)
    out["violations"] = [{k: v for k, v in x.items() if k != "explain"} for x in rule["violations"]]
    return out


def _assert_same(logs: dict[str, Any], index: dict[str, Any], paths: dict[str, str]) -> int:
    """Per robot, every rule the index can decide is the logs' answer; the others name the
    signal the index lacks. The number of violations compared."""
    assert [r["robot"] for r in logs["robots"]] == [r["robot"] for r in index["robots"]]
    compared = 0
    for on_log, on_index in zip(logs["robots"], index["robots"], strict=True):
        for key in ("period_ns", "cycles"):
            assert on_log[key] == on_index[key]
        assert on_log["clock"]["start_ns"] == on_index["clock"]["start_ns"]
        if on_log["clock"]["name"] == "system":  # a wall clock: the index says so by its days
            assert on_index["clock"] == on_log["clock"]
        for a, b in zip(on_log["rules"], on_index["rules"], strict=True):
            assert _without_explain(a) == _without_explain(b)
            for v in b["violations"]:
                robot = on_index["robot"]
                path = paths[robot]
                assert v["explain"] == (
                    f"trace-audit explain {path} --cycle {v['first_cycle']} --robot {robot}"
                )
                compared += 1
    return compared


def test_two_sim_robots_give_the_logs_answer_from_the_index(tmp_path: Path) -> None:
    root = tmp_path / "root"
    _sim(root, "amr-1", 1)
    _sim(root, "amr-2", 2)
    index = _index(root, tmp_path / "idx")
    rules = str(_rules_file(tmp_path))
    code_log, logs = _check(str(root), "--rules", rules)
    code_index, fleet = _check("--index", str(index), "--rules", rules)
    assert code_log == code_index == 1  # never_stop and keep_3m fail
    paths = {r: str(root / "hot" / f"{r}_000000.mcap") for r in ("amr-1", "amr-2")}
    assert _assert_same(logs, fleet, paths) > 0
    outcomes = {r["rule"]: r["outcome"] for r in fleet["robots"][0]["rules"]}
    assert outcomes["never_stop"] == "violated"
    assert outcomes["stop_response_passes"] == "not_decidable"  # checked on STOP cycles only
    assert "groups" not in fleet and "groups" not in logs

    _, one = _check("--index", str(index), "--rules", rules, "--robot", "amr-2")
    assert [r["robot"] for r in one["robots"]] == ["amr-2"]
    assert one["robots"][0] == fleet["robots"][1]


def test_a_gap_is_the_same_not_decidable_stretch_from_the_index(tmp_path: Path) -> None:
    log = write_log(tmp_path / "gap.mcap", [stretch("clear", 40)], skip=lambda i: 20 <= i < 25)
    index = _index(log, tmp_path / "idx")
    rules = tmp_path / "r.toml"
    rules.write_text(
        '[[rule]]\nname = "soon_continue"\n'
        'stl = "always(eventually[0:0.3](command.CONTINUE > 0.5))"\n'
        '[[rule]]\nname = "never_continue"\nstl = "always(command.CONTINUE < 0.5)"\n'
    )
    _, logs = _check(str(log), "--rules", str(rules))
    _, fleet = _check("--index", str(index), "--rules", str(rules))
    # The index does not name a clock that tells no time of day: its times read as seconds.
    assert fleet["robots"][0].pop("clock") == {"name": NOT_WALL_CLOCK, "start_ns": 100 * 10**9}
    assert logs["robots"][0].pop("clock")["start_ns"] == 100 * 10**9
    assert logs["robots"] == fleet["robots"]  # the explain commands too: the same file
    (gap,) = [u for u in fleet["robots"][0]["rules"][0]["undecided"] if u["reason"] == "gap"]
    assert (gap["first_cycle"], gap["last_cycle"], gap["gap"]["missing_cycles"]) == (17, 24, 5)
    assert fleet["robots"][0]["rules"][1]["violations"]


def test_by_robot_and_day_splits_a_wall_clock_run_at_midnight(tmp_path: Path) -> None:
    root = tmp_path / "root"
    _sim(root, "amr-1", 3, "--start", "2026-05-04T23:59:30Z")
    index = _index(root, tmp_path / "idx")
    rules = str(_rules_file(tmp_path))
    _, logs = _check(str(root), "--rules", rules)
    _, fleet = _check("--index", str(index), "--rules", rules, "--by", "robot,day")
    assert _assert_same(logs, fleet, {"amr-1": str(root / "hot" / "amr-1_000000.mcap")}) >= 0
    days = [(g["robot"], g["day"], g["cycles"]) for g in fleet["groups"]]
    assert days == [("amr-1", "2026-05-04", 300), ("amr-1", "2026-05-05", 300)]
    whole = {r["rule"]: r for r in fleet["robots"][0]["rules"]}
    for name, rule in whole.items():
        parts = [next(x for x in g["rules"] if x["rule"] == name) for g in fleet["groups"]]
        assert sum(p["decidable_cycles"] for p in parts) == rule["decidable_cycles"]
        assert sum(p["violations"] for p in parts) >= len(rule["violations"])
        lows = [p["robustness"] for p in parts if p["robustness"] is not None]
        assert (min(lows) if lows else None) == rule["robustness"]
        if rule["outcome"] == "violated":
            assert any(p["outcome"] == "violated" for p in parts)
    code, out, _ = _run("check", "--index", str(index), "--rules", rules, "--by", "robot,day")
    assert code == 1 and "By robot and day" in out and "2026-05-05" in out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--robot", "amr-9"], "robot 'amr-9' is not in this index; it holds amr-7"),
        (["--by", "hour"], "cannot group rules by 'hour'"),
        (["--from", "+1"], "--from/--to are not supported with --index"),
        (["LOG"], "give either a log or --index INDEX"),
    ],
)
def test_index_usage_errors_are_exit_2_in_one_line(
    tmp_path: Path, sample_log: Path, args: list[str], message: str
) -> None:
    index = _index(sample_log, tmp_path / "idx")
    rules = tmp_path / "r.toml"
    rules.write_text('[[rule]]\nname = "ok"\nstl = "always(command.STOP < 1.5)"\n')
    args = [str(sample_log) if a == "LOG" else a for a in args]
    code, out, err = _run("check", "--index", str(index), "--rules", str(rules), *args)
    assert code == 2 and out == "" and err.count("\n") == 1 and message in err


def test_by_without_an_index_and_a_missing_index(tmp_path: Path, sample_log: Path) -> None:
    rules = tmp_path / "r.toml"
    rules.write_text('[[rule]]\nname = "ok"\nstl = "always(command.STOP < 1.5)"\n')
    code, _, err = _run("check", str(sample_log), "--rules", str(rules), "--by", "robot,day")
    assert code == 2 and "need --index" in err
    code, _, err = _run("check", "--index", str(tmp_path / "none"), "--rules", str(rules))
    assert code == 3 and "not a fleet index" in err


def test_scheduler_fans_robots_out_over_dask_with_the_local_json(tmp_path: Path) -> None:
    pytest.importorskip("distributed")
    from trace_audit.fleet.local import LocalDask

    root = tmp_path / "root"
    _sim(root, "amr-1", 1)
    _sim(root, "amr-2", 2)
    index = _index(root, tmp_path / "idx")
    rules = str(_rules_file(tmp_path))
    args = ("--index", str(index), "--rules", rules, "--by", "robot,day")
    _, local = _check(*args)
    with LocalDask(tmp_path / "dask", pythonpath=ROOT) as cluster:
        cluster.add_worker()
        # a process of its own, as a user runs it: the Dask client's sockets close with it
        # (in this process they would be left to the garbage collector, warning later)
        argv = [sys.executable, "-m", "trace_audit.cli", "check", *args]
        done = subprocess.run(
            [*argv, "--scheduler", cluster.address, "--json"],
            capture_output=True,
            text=True,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
            check=False,
            timeout=300,
        )
    assert done.returncode == 1, done.stderr
    assert json.loads(done.stdout) == local
