"""``trace-audit find INDEX --robot``: repeatable, the robots ORed as SQL parameters, and a
robot the index does not hold is one line naming those it does (exit 2)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.outside import cli, one_line
from tests.trace_audit.conftest import stretch, write_log
from trace_audit.fleet.find import find_decisions, index_robots
from trace_audit.fleet.index import build_index

SCRIPT = (stretch("clear", 5), stretch("ped_close", 5))
ROBOTS = ("amr-1", "amr-2", "amr-3")


@pytest.fixture(scope="module")
def index(tmp_path_factory: pytest.TempPathFactory) -> Path:
    base = tmp_path_factory.mktemp("find-robots")
    for i, robot in enumerate(ROBOTS):
        write_log(base / "logs", SCRIPT, robot_id=robot, t0_ns=100_000_000_000 + i * 1_000_000)
    build_index([base / "logs"], base / "idx")
    return base / "idx"


def _robots(*args: str | Path) -> list[str]:
    done = cli("find", *args, "--json")
    assert done.returncode == 0, done.stderr
    return sorted({row["robot"] for row in json.loads(done.stdout)})


def test_the_index_holds_every_robot(index: Path) -> None:
    assert index_robots(index) == sorted(ROBOTS)


def test_without_robot_every_robot_is_found(index: Path) -> None:
    assert _robots(index) == sorted(ROBOTS)


def test_one_robot_finds_its_decisions_only(index: Path) -> None:
    assert _robots(index, "--robot", "amr-2") == ["amr-2"]
    stops = cli("find", index, "--robot", "amr-2", "--action", "STOP", "--json")
    rows = json.loads(stops.stdout)
    assert len(rows) == 5 and {r["command"] for r in rows} == {"STOP"}


def test_robot_repeated_finds_either(index: Path) -> None:
    assert _robots(index, "--robot", "amr-1", "--robot", "amr-3") == ["amr-1", "amr-3"]
    twice = cli("find", index, "--robot", "amr-1", "--robot", "amr-1", "--json")
    assert len(json.loads(twice.stdout)) == 10  # given twice, counted once


def test_a_robot_the_index_does_not_hold_is_one_line_naming_those_it_holds(index: Path) -> None:
    done = cli("find", index, "--robot", "amr-1", "--robot", "amr-9")
    one_line(done, 2, "'amr-9'", "amr-1, amr-2, amr-3")
    assert "'amr-1'" not in done.stderr and done.stdout == ""


def test_an_id_that_looks_like_sql_is_a_robot_the_index_does_not_hold(index: Path) -> None:
    done = cli("find", index, "--robot", "x' OR '1'='1")
    one_line(done, 2, "is not in this index")


def test_the_library_takes_robots(index: Path) -> None:
    found = find_decisions(index, robots=["amr-2", "amr-1"], action="stop")
    assert {row[0] for row in found.rows} == {"amr-1", "amr-2"} and len(found.rows) == 10
