"""A fleet in one log root, from the outside: three ``trace-sim`` robots (two on sim clocks,
one on a wall clock from ``--start``) and a profile 1.1 arm logging into one root, indexed
with ``trace-audit index``. Pins the ``day`` partitions (the UTC day on a wall clock, the
robot's run otherwise, never 1970), the ``channels`` and ``checks`` tables row for row
against the log, and ``find``'s explain commands, run as printed."""

from __future__ import annotations

import json
import shlex
import shutil
import subprocess
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import pytest

from tests.outside import REPO, cli
from tests.sim.test_fleet_options import WALL_START, sim_cli
from trace_runtime import open_log
from trace_runtime.records import TOPIC_EXECUTION

SIM_ROBOTS = {"amr-1": (), "amr-2": (), "amr-3": ("--start", WALL_START)}


def _sim(root: Path, robot: str, *extra: str, duration: str = "30s", seed: int = 1) -> None:
    done = sim_cli(
        "run",
        "--duration",
        duration,
        "--seed",
        str(seed),
        "--robot-id",
        robot,
        "--out",
        root,
        "--json",
        *extra,
    )
    assert done.returncode == 0, done.stderr


def _json(*args: str | Path) -> Any:
    done = cli(*args, "--json")
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def _rows(index: Path, sql: str) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = _json("query", index, sql)
    return rows


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(the root, its index): three simulated robots and the pick-and-place arm."""
    base = tmp_path_factory.mktemp("fleet-root")
    root = base / "fleet"
    for seed, (robot, extra) in enumerate(SIM_ROBOTS.items(), start=1):
        _sim(root, robot, *extra, seed=seed)
    arm = subprocess.run(
        [sys.executable, str(REPO / "examples" / "pick_and_place_arm.py"), "--out", str(root)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert arm.returncode == 0, arm.stderr
    index = base / "idx"
    report = _json("index", root, "--out", index)
    assert report["segments"] == 4
    return root, index


def test_each_robot_is_partitioned_by_its_utc_day_or_its_run_never_1970(
    fleet: tuple[Path, Path],
) -> None:
    _, index = fleet
    days = _rows(index, "SELECT robot, day, count(*) AS n FROM decisions GROUP BY ALL")
    assert {(r["robot"], r["day"]) for r in days} == {
        ("amr-1", "run-000000"),
        ("amr-2", "run-000000"),
        ("amr-3", "2026-05-04"),  # --start 2026-05-04T06:00:00Z: a wall clock
        ("arm-1", "run-000000"),  # a system clock counting from 0 is not a time of day
    }
    assert not [p for p in index.rglob("*") if "1970" in p.name]
    for table in ("entities", "checks", "gaps", "segments"):
        got = {r["day"] for r in _rows(index, f"SELECT DISTINCT day FROM {table}")}
        assert got <= {"run-000000", "2026-05-04"}, table


def test_metrics_by_robot_and_day_names_runs_and_says_what_day_means(
    fleet: tuple[Path, Path],
) -> None:
    _, index = fleet
    report = _json("metrics", "--index", index, "--by", "robot,day")
    names = {g["name"] for g in report["groups"]}
    assert names == {"amr-1, run-000000", "amr-2, run-000000", "amr-3, 2026-05-04",
                     "arm-1, run-000000"}  # fmt: skip
    assert "run-<number of the run's first segment>" in report["definitions"]["day"]


def _layer_rows(root: Path, robot: str, build: Any) -> Counter[tuple[Any, ...]]:
    log = open_log(root)
    rows: Counter[tuple[Any, ...]] = Counter()
    for segment in log.segments_of(robot):
        for cycle in segment.iter_cycles():
            execution = cycle.layer(TOPIC_EXECUTION)
            if isinstance(execution, dict):
                rows.update(build(cycle, execution))
    return rows


def test_the_channels_table_holds_every_logged_channel_with_its_units(
    fleet: tuple[Path, Path],
) -> None:
    root, index = fleet
    got = Counter(
        tuple(r.values())
        for r in _rows(
            index,
            "SELECT cycle, t_ns, channel, intended, actual, deviation, unit, deviation_unit "
            "FROM channels WHERE robot = 'arm-1'",
        )
    )
    want = _layer_rows(
        root,
        "arm-1",
        lambda c, e: [
            (
                c.cycle,
                c.t_ns,
                ch["name"],
                ch.get("intended"),
                ch.get("actual"),
                ch.get("deviation"),
                ch["unit"],
                e.get("deviation_unit"),
            )
            for ch in e.get("channels", ())
        ],
    )
    assert got == want and sum(want.values()) > 0
    assert {k[6] for k in want} >= {"rad/s", "N"} and {k[7] for k in want} == {"m/s"}
    (row,) = _rows(index, "SELECT DISTINCT deviation_unit FROM decisions WHERE robot = 'arm-1'")
    assert row["deviation_unit"] == "m/s"
    # trace-sim logs a mobile base's planar motion (profile 1.0): no channels
    assert _rows(index, "SELECT count(*) AS n FROM channels WHERE robot <> 'arm-1'")[0]["n"] == 0


@pytest.mark.parametrize("robot", ["amr-1", "amr-3", "arm-1"])
def test_the_checks_table_holds_every_rule_checked(fleet: tuple[Path, Path], robot: str) -> None:
    root, index = fleet
    got = Counter(
        tuple(r.values())
        for r in _rows(
            index,
            'SELECT cycle, t_ns, rule, passed, value, "limit", detail FROM checks '
            f"WHERE robot = '{robot}'",
        )
    )
    want = _layer_rows(
        root,
        robot,
        lambda c, e: [
            (
                c.cycle,
                c.t_ns,
                k["rule"],
                k["passed"],
                k.get("value"),
                k.get("limit"),
                k.get("detail"),
            )
            for k in e.get("checks", ())
        ],
    )
    assert got == want and sum(want.values()) > 0


def test_find_prints_explain_commands_that_name_the_exact_decision(
    fleet: tuple[Path, Path], tmp_path: Path
) -> None:
    _, index = fleet
    found = _json("find", index, "--action", "STOP", "--limit", "200")
    robots = {r["robot"] for r in found}
    assert {"amr-1", "amr-3"} <= robots
    picked = [next(r for r in found if r["robot"] == robot) for robot in sorted(robots)]
    for row in picked:
        command = row["explain"]
        assert "--t" not in command and "e+" not in command, command
        words = shlex.split(command)
        assert words[:2] == ["trace-audit", "explain"]
        assert Path(words[2]).is_absolute() and Path(words[2]).is_file()
        assert words[3:] == ["--cycle", str(row["cycle"]), "--robot", row["robot"]]
        # run as printed, from another directory
        done = subprocess.run(
            [sys.executable, "-m", "trace_audit.cli", *words[1:], "--json"],
            capture_output=True,
            text=True,
            check=False,
            cwd=tmp_path,
            env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
            timeout=120,
        )
        assert done.returncode == 0, done.stderr
        explained = json.loads(done.stdout)
        assert (explained["robot"], explained["cycle"], explained["t_ns"]) == (
            row["robot"],
            row["cycle"],
            row["t_ns"],
        )
        assert explained["decision"]["command"] == "STOP"


def test_an_explain_command_quotes_a_path_a_shell_would_split(tmp_path: Path) -> None:
    root = tmp_path / "logs of 'amr'"
    _sim(root, "amr-5", duration="2s")
    index = tmp_path / "idx"
    _json("index", root, "--out", index)
    (row, *_) = _json("find", index, "--limit", "1")
    words = shlex.split(row["explain"])
    assert Path(words[2]) == (root / "hot" / "amr-5_000000.mcap").resolve()
    done = cli(*words[1:], "--json")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["cycle"] == row["cycle"]


def test_two_roots_of_distinct_robots_index_together(tmp_path: Path) -> None:
    """``trace-audit index sim1 sim2``: refused while both robots were amr-01."""
    _sim(tmp_path / "sim1", "amr-1", duration="2s")
    _sim(tmp_path / "sim2", "amr-2", duration="2s", seed=2)
    report = _json("index", tmp_path / "sim1", tmp_path / "sim2", "--out", tmp_path / "idx")
    assert report["segments"] == 2
    per_robot = _rows(tmp_path / "idx", "SELECT robot, count(*) AS n FROM decisions GROUP BY ALL")
    assert {r["robot"] for r in per_robot} == {"amr-1", "amr-2"}


def test_a_restarted_sim_clock_starts_a_new_run_partition(tmp_path: Path) -> None:
    """A second run into the root continues amr-1's chain from segment 1 on a clock back
    at 0 (``--start 0``: a continued sim robot's clock otherwise goes on): its rows are a
    run of their own, named by its first segment."""
    root = tmp_path / "root"
    _sim(root, "amr-1", duration="2s")
    _sim(root, "amr-1", "--start", "0", duration="2s", seed=2)
    _json("index", root, "--out", tmp_path / "idx")
    rows = _rows(
        tmp_path / "idx",
        "SELECT day, min(cycle) AS first, min(t_ns) AS t0 FROM decisions GROUP BY ALL ORDER BY 1",
    )
    assert [(r["day"], r["t0"]) for r in rows] == [("run-000000", 0), ("run-000001", 0)]
    assert rows[1]["first"] > rows[0]["first"]


def _readme_fleet_commands() -> list[list[str]]:
    text = (REPO / "README.md").read_text(encoding="utf-8")
    block = text.split("Robots with distinct ids share", 1)[1].split("```sh", 1)[1]
    lines = [line.split("#", 1)[0].strip() for line in block.split("```", 1)[0].splitlines()]
    return [shlex.split(line) for line in lines if line]


def test_the_readme_fleet_commands_run_as_written(tmp_path: Path) -> None:
    """Shorter runs (20 s, not 10 min), else word for word, in a fresh directory holding
    the checkout's rules files (the README's commands run from the checkout)."""
    shutil.copytree(REPO / "docs" / "rules", tmp_path / "docs" / "rules")
    commands = _readme_fleet_commands()
    assert [c[0] for c in commands].count("trace-sim") == 3
    modules = {"trace-sim": "evaluation.cli", "trace-audit": "trace_audit.cli"}
    outputs = []
    for words in commands:
        args = ["20s" if w == "10m" else w for w in words[1:]]
        done = subprocess.run(
            [sys.executable, "-m", modules[words[0]], *args, "--json"],
            capture_output=True,
            text=True,
            check=False,
            cwd=tmp_path,
            env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
            timeout=120,
        )
        # check exits 1 when a rule is violated (a finding, as verify's)
        assert done.returncode in ((0, 1) if "check" in words else (0,)), (words, done.stderr)
        outputs.append(json.loads(done.stdout))
    days = {(r["robot"], r["day"]) for r in outputs[4]}
    assert days == {("amr-1", "run-000000"), ("amr-2", "run-000000"), ("amr-3", "2026-05-04")}
    (checked,) = [o for o, w in zip(outputs, commands, strict=True) if "check" in w]
    groups = {(g["robot"], g["day"]) for g in checked["groups"]}
    assert groups == days  # each rule's outcome per robot and day
