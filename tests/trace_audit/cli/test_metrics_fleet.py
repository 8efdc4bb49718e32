"""``trace-audit metrics`` on a root of several robots: a row per robot, ``--robot``,
the failed execution checks table in the log's clock, and ``--jobs 2`` as ``--jobs 1``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from tests.trace_audit.conftest import T0_NS, stretch, write_log
from tests.trace_audit.metrics.test_failed_checks import expected_failures, two_robot_root
from tests.trace_audit.metrics.test_scan import HandLog, layers
from trace_audit.cli import app

WALL_T0_NS = 1_777_874_664_900_000_000
"""2026-05-04T06:04:24.900Z: a system-clock log's first time."""


def run(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(app, ["metrics", *args], terminal_width=120)
    return result.exit_code, result.stdout, result.stderr


def _json(*args: str) -> dict[str, Any]:
    code, out, err = run(*args, "--json")
    assert code == 0, err
    data: dict[str, Any] = json.loads(out)
    for name in ("elapsed_s", "cycles_per_s"):
        data.pop(name)
    return data


@pytest.fixture
def fleet(tmp_path: Path) -> Path:
    root = tmp_path / "fleet"
    write_log(root, robot_id="amr-1")
    write_log(root, (stretch("clear", 40),), robot_id="amr-2", t0_ns=T0_NS + 50_000_000)
    return root


def test_each_robot_is_a_row(fleet: Path) -> None:
    data = _json(str(fleet))
    assert data["by"] == "robot"
    assert [(r["group"], r["decisions"]) for r in data["table_iii"]] == [
        ("amr-1", 100),
        ("amr-2", 40),
    ]
    code, out, _ = run(str(fleet), "--plain")
    assert code == 0 and "Per robot" in out
    assert "Failed execution checks" not in out  # these robots' checks all pass


def test_robot_selects_exactly_that_robots_cycles(fleet: Path, tmp_path: Path) -> None:
    alone = tmp_path / "alone"
    write_log(alone, (stretch("clear", 40),), robot_id="amr-2", t0_ns=T0_NS + 50_000_000)
    selected = _json(str(fleet), "--robot", "amr-2")
    own = _json(str(alone))
    assert selected["robots"] == ["amr-2"] and "robots" not in own
    assert selected["overall"] == own["overall"] and selected["overall"]["decisions"] == 40
    assert selected["table_iii"] == [] and selected["by"] is None
    code, out, _ = run(str(fleet), "--robot", "amr-2", "--plain")
    assert code == 0 and "Auditability of 40 decisions in 1 segment" in out and "amr-2)" in out


def test_robot_repeated_reads_those_robots(fleet: Path) -> None:
    data = _json(str(fleet), "--robot", "amr-1", "--robot", "amr-2")
    assert [r["group"] for r in data["table_iii"]] == ["amr-1", "amr-2"]


def test_an_unknown_robot_exits_2_with_one_line_naming_the_robots(fleet: Path) -> None:
    code, out, err = run(str(fleet), "--robot", "amr-9")
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "amr-9" in err and "amr-1, amr-2" in err


def test_robot_is_refused_with_index(tmp_path: Path) -> None:
    code, _, err = run("--index", str(tmp_path), "--robot", "amr-1")
    assert code == 2 and "--robot" in err


def test_failed_checks_json_and_table(tmp_path: Path) -> None:
    root, written = two_robot_root(tmp_path)
    data = _json(str(root))
    rows = data["failed_checks"]["rules"]
    expected = expected_failures(written)
    assert {(r["robot"], r["rule"]): r["failed"] for r in rows} == {
        key: value[0] for key, value in expected.items()
    }
    code, out, _ = run(str(root), "--plain")
    assert code == 0 and "Failed execution checks" in out
    n, first_t_ns, first_cycle, last_t_ns, last_cycle = expected["r1", "min_clearance"]
    lines = out.splitlines()
    at = next(i for i, x in enumerate(lines) if x.startswith("r1") and "min_clearance" in x)
    assert _cells(lines[at]) == [
        "r1",
        "min_clearance",
        str(n),
        "first",
        str(first_cycle),
        f"{first_t_ns / 1e9:.3f} s",
    ]
    assert _cells(lines[at + 1]) == [
        "",
        "",
        "",
        "last",
        str(last_cycle),
        f"{last_t_ns / 1e9:.3f} s",
    ]


def _cells(line: str) -> list[str]:
    return [cell.strip() for cell in line.split("|")]


def test_jobs_2_gives_the_same_json_as_jobs_1(tmp_path: Path) -> None:
    root, _ = two_robot_root(tmp_path)
    one = _json(str(root), "--jobs", "1", "--failures")
    two = _json(str(root), "--jobs", "2", "--failures")
    assert one == two and one["failed_checks"]["rules"]


def test_failed_check_times_read_as_iso_on_a_wall_clock(tmp_path: Path) -> None:
    log = HandLog(tmp_path / "wall.mcap")
    for i in range(5):
        at = WALL_T0_NS + i * 100_000_000
        record = layers(log.sensor(at, {"i": i}))
        record["execution"]["checks"] = [
            {"rule": "max_speed", "passed": i not in (1, 3), "value": 1.2, "limit": 1.0}
        ]
        log.cycle(i, at, record)
    log.close()
    code, out, _ = run(str(log.path), "--plain")
    assert code == 0
    lines = out.splitlines()
    at = next(i for i, x in enumerate(lines) if "max_speed" in x)
    assert _cells(lines[at]) == [
        "amr-7",
        "max_speed",
        "2",
        "first",
        "1",
        "2026-05-04T06:04:25.000Z (+0.100 s)",
    ]
    assert _cells(lines[at + 1])[3:] == ["last", "3", "2026-05-04T06:04:25.200Z (+0.300 s)"]
