"""``trace-audit catalog``: a robot id is never cut, in a pipe, with ``--plain`` or on a
narrow console; the times and the tier wrap instead."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.outside import cli
from tests.trace_audit.conftest import stretch, write_log
from trace_audit.cli import app

WALL_T0_NS = 1_777_874_664_000_000_000  # 2026-05-04: the times print as UTC dates (wide)
ROBOTS = ("amr-1", "tractor-long-name-03")


@pytest.fixture(scope="module")
def root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    base = tmp_path_factory.mktemp("catalog-robots") / "root"
    for i, robot in enumerate(ROBOTS):
        write_log(base, (stretch("clear", 5),), robot_id=robot, t0_ns=WALL_T0_NS + i * 10**9)
    return base


def _rows(text: str) -> list[str]:
    """The first cell of each table line that names a robot (ASCII or heavy boxes)."""
    cells = [line.replace("|", " ").split() for line in text.splitlines()]
    return [c[0] for c in cells if c and c[0] in ROBOTS]


def test_in_a_pipe_every_robot_id_is_whole(root: Path) -> None:
    done = cli("catalog", root)
    assert done.returncode == 0, done.stderr
    assert _rows(done.stdout) == list(ROBOTS), done.stdout
    assert "…" not in "".join(line.split()[0] for line in done.stdout.splitlines() if line)


def test_plain_every_robot_id_is_whole(root: Path) -> None:
    done = cli("catalog", root, "--plain")
    assert done.returncode == 0, done.stderr
    assert _rows(done.stdout) == list(ROBOTS), done.stdout
    assert "2026-05-04" in done.stdout


@pytest.mark.parametrize("columns", ["120", "80", "60", "40"])
def test_on_a_narrow_console_the_robot_is_not_the_column_cut(root: Path, columns: str) -> None:
    shown = CliRunner(env={"COLUMNS": columns}).invoke(app, ["catalog", str(root)])
    assert shown.exit_code == 0, shown.output
    assert _rows(shown.stdout) == list(ROBOTS), shown.stdout


def test_at_eighty_columns_the_times_wrap_rather_than_vanish(tmp_path: Path) -> None:
    short = tmp_path / "root"
    write_log(short, (stretch("clear", 5),), robot_id="amr-7", t0_ns=WALL_T0_NS)
    shown = CliRunner(env={"COLUMNS": "80"}).invoke(app, ["catalog", str(short)])
    assert "2026-05-04" in shown.stdout and "06:04:24" in shown.stdout, shown.stdout
    assert "…" not in shown.stdout
