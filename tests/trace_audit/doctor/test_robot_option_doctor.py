"""``trace-audit doctor ROOT --robot``: a root of several robots is checked whole or cut to some
of its robots (``selection.Selection``), and each problem names its robot."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.outside import cli, one_line
from tests.trace_audit.conftest import stretch, write_log

SHORT = (stretch("clear", 12),)


@pytest.fixture
def fleet(tmp_path: Path) -> Path:
    """amr-1 closed its segment; amr-2 crashed (its file is not closed: a SHOULD note)."""
    root = tmp_path / "root"
    write_log(root, SHORT, robot_id="amr-1")
    write_log(root, SHORT, robot_id="amr-2", finish=False)
    return root


def test_each_problem_of_a_root_of_several_robots_names_its_robot(fleet: Path) -> None:
    done = cli("doctor", fleet, "--plain")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert any(line.split() == ["robots", "amr-1,", "amr-2"] for line in lines), done.stdout
    header = next(line for line in lines if "rule" in line and "where" in line)
    assert header.split() == ["robot", "rule", "where", "what"]
    closed = next(line for line in lines if "§1 closed" in line)
    assert closed.split()[0] == "amr-2"


def test_robot_selects_that_robots_segments_only(fleet: Path) -> None:
    done = cli("doctor", fleet, "--robot", "amr-2", "--json")
    assert done.returncode == 0, done.stderr
    body = json.loads(done.stdout)
    assert [Path(s["path"]).name for s in body["segments"]] == ["amr-2_000000.mcap"]
    assert [s["robot"] for s in body["segments"]] == ["amr-2"]
    assert [p["rule"] for p in body["segments"][0]["problems"]] == ["closed"]

    clean = json.loads(cli("doctor", fleet, "--robot", "amr-1", "--json").stdout)
    assert [s["robot"] for s in clean["segments"]] == ["amr-1"]
    assert clean["conforms"] and clean["segments"][0]["problems"] == []


def test_robot_is_repeatable_and_counts_once(fleet: Path) -> None:
    args = ("--robot", "amr-1", "--robot", "amr-2", "--robot", "amr-1", "--json")
    body = json.loads(cli("doctor", fleet, *args).stdout)
    assert [s["robot"] for s in body["segments"]] == ["amr-1", "amr-2"]


def test_one_robot_selected_prints_as_a_one_robot_log(fleet: Path, tmp_path: Path) -> None:
    """The text of a root cut to one robot is that of a root holding only that robot."""
    alone = tmp_path / "solo"  # as long a name as the fleet's: the title's rule matches
    write_log(alone, SHORT, robot_id="amr-2", finish=False)
    cut = cli("doctor", fleet, "--robot", "amr-2", "--plain").stdout
    whole = cli("doctor", alone, "--plain").stdout
    assert cut.replace(str(fleet), "ROOT") == whole.replace(str(alone), "ROOT")
    assert "robots" not in whole and "amr-2" not in whole.replace(str(alone), "")


def test_a_robot_the_log_does_not_hold_is_one_line_naming_those_it_does(tmp_path: Path) -> None:
    root = tmp_path / "root"
    for robot in ("amr-1", "amr-2"):
        write_log(root, SHORT, robot_id=robot)
    done = cli("doctor", root, "--robot", "amr-9")
    one_line(done, 2, "'amr-9'", "amr-1, amr-2")
    assert done.stdout == ""
